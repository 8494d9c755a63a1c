"""Session-wide test setup."""

import pytest


@pytest.fixture(autouse=True, scope="session")
def _checkpoint_key(tmp_path_factory):
    """Checkpoints are signed with a key of the session's own (subprocesses inherit the
    variable), never the user's key under ~/.local/share."""
    from airspace_sim.world.checkpoint import KEY_ENV

    mp = pytest.MonkeyPatch()
    mp.setenv(KEY_ENV, str(tmp_path_factory.mktemp("key") / "checkpoint.key"))
    yield
    mp.undo()

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


@pytest.fixture(scope="module")
def local_ray():
    """A local Ray with 2 CPUs for one test module (the Ray backend and RLlib tests),
    shut down after it."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()

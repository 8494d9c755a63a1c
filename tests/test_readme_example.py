"""The README's Python API example runs as written, and what it shows holds: the smoothers'
estimates of the recorded tracks are closer to the simulated truth than the filter's were,
the fixed-interval one's closest."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def python_api_example() -> str:
    text = README.read_text()
    section = text[text.index("## Python API") :]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_python_api_example_runs_and_smoothing_beats_filtering(capsys):
    ns: dict = {}
    exec(compile(python_api_example(), str(README), "exec"), ns)
    sm, record, truth = ns["sm"], ns["record"], ns["truth"]
    K = len(record)
    assert sm.x.shape == (K, 10, 5) and sm.mu.shape == (K, 10, 3)
    np.testing.assert_allclose(sm.mu.sum(axis=2), 1.0, rtol=1e-9)
    true_xy = truth.states[2 : 2 + K, :10][..., [0, 2]]
    filtered = np.array([np.einsum("bm,bmn->bn", mu, xm) for mu, xm, _ in record])
    err_f = np.sqrt(np.mean(np.sum((filtered[..., [0, 2]] - true_xy) ** 2, axis=-1)))
    err_s = np.sqrt(np.mean(np.sum((sm.x[..., [0, 2]] - true_xy) ** 2, axis=-1)))
    err_late = np.sqrt(np.mean(np.sum((ns["late"].x[..., [0, 2]] - true_xy) ** 2, axis=-1)))
    assert err_s < 0.8 * err_f and err_s < err_late < err_f
    assert "average NIS" in capsys.readouterr().out

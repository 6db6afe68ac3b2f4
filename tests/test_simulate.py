import subprocess
import sys

import numpy as np
import pytest

from quad_envs.simulate import simulate_case
from quad_envs.trajectories import TRAJECTORY_NAMES, make_trajectory


def test_case_c_reproduces_the_authors_run(reference_case_c, tmp_path):
    """The simulate command writes the authors' published case C run to 1e-9."""
    out = tmp_path / "c.csv"
    subprocess.run(
        [sys.executable, "-m", "quad_sindy", "simulate", "--case", "C", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    header = out.read_text().splitlines()[0].split(",")
    assert header[:9] == ["t", "y", "z", "phi", "y_dot", "z_dot", "phi_dot", "u1", "u2"]
    ours = np.loadtxt(out, delimiter=",", skiprows=1)
    assert ours.shape == reference_case_c.shape
    np.testing.assert_allclose(ours, reference_case_c, rtol=0, atol=1e-9)


@pytest.mark.parametrize("case,settle_err", [("A", 1e-3), ("B", 1e-3), ("C", 1e-3)])
def test_planar_pd_tracks_the_paper_cases(case, settle_err):
    run = simulate_case(case)
    err = np.abs(run.states[:, :2] - run.refs[:, :2])
    assert np.all(np.isfinite(run.states))
    assert err[-1].max() < settle_err  # settled on the final point
    assert err.max() < 0.6  # bounded transient (A's step is 0.5 m)
    assert np.abs(run.states[:, 2]).max() < 1.0


@pytest.mark.parametrize("case", ["A", "B", "C", "figure8", "random", "hover"])
def test_6dof_controller_flies_the_3d_references(case):
    run = simulate_case(case, system="quad6dof", duration=12.0)
    err = np.abs(run.states[:, :3] - run.refs[:, :3])
    assert np.all(np.isfinite(run.states))
    assert err[len(err) // 2 :].max() < 0.05, err.max(axis=0)


def test_trajectories_are_consistent_derivatives():
    """Velocity is the derivative of position and acceleration that of velocity (smooth parts)."""
    rng = np.random.default_rng(0)
    for name in ("sine", "figure8", "random"):
        for ndim in (2, 3):
            traj = make_trajectory(name, ndim=ndim, rng=rng)
            t = np.linspace(0.05, 2.9, 200)
            h = 1e-6
            nd = traj.ndim
            ref_p, ref_m = traj(t + h), traj(t - h)
            ref = traj(t)
            np.testing.assert_allclose(
                (ref_p[:, :nd] - ref_m[:, :nd]) / (2 * h), ref[:, nd : 2 * nd], atol=1e-5
            )
            np.testing.assert_allclose(
                (ref_p[:, nd : 2 * nd] - ref_m[:, nd : 2 * nd]) / (2 * h),
                ref[:, 2 * nd : 3 * nd],
                atol=1e-4,
            )


def test_diamond_corners_and_unknown_names():
    diamond = make_trajectory("C")
    np.testing.assert_allclose(diamond(0.0)[:2], [0, 1.8])
    np.testing.assert_allclose(diamond(8.0)[:2], [0, 1.8], atol=1e-12)  # closed
    np.testing.assert_allclose(
        diamond(2.0)[:2], [0.5 * np.cos(np.pi / 4), 1.8 + 0.5 * np.sin(np.pi / 4)]
    )
    with pytest.raises(ValueError, match="valid choices: " + ", ".join(TRAJECTORY_NAMES)):
        make_trajectory("circle")

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from quad_envs.simulate import simulate_case
from quad_envs.trajectories import TRAJECTORY_NAMES, make_trajectory

TEST_DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def simulated_case_c(tmp_path_factory) -> tuple[list[str], np.ndarray]:
    """``quad-sindy simulate --case C``: its header and its rows."""
    out = tmp_path_factory.mktemp("sim") / "c.csv"
    subprocess.run(
        [sys.executable, "-m", "quad_sindy", "simulate", "--case", "C", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    return out.read_text().splitlines()[0].split(","), np.loadtxt(out, delimiter=",", skiprows=1)


def _check_against_authors(simulated: tuple[list[str], np.ndarray], authors: np.ndarray) -> None:
    """The authors' 15 columns are ours (applied inputs = commanded: no saturation in C)."""
    header, ours = simulated
    assert header[:9] == ["t", "y", "z", "phi", "y_dot", "z_dot", "phi_dot", "u1", "u2"]
    assert header[15:] == ["u1_cmd", "u2_cmd"]
    rows = np.searchsorted(ours[:, 0], authors[:, 0] - 1e-9)
    ours = ours[rows]
    assert ours[:, :15].shape == authors.shape
    np.testing.assert_allclose(ours[:, :15], authors, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours[:, 15:], authors[:, 7:9], rtol=0, atol=1e-9)


def test_case_c_reproduces_the_authors_run(simulated_case_c, reference_case_c):
    """The simulate command writes the authors' published case C run to 1e-9 (full file)."""
    _check_against_authors(simulated_case_c, reference_case_c)


def test_case_c_reproduces_the_authors_excerpt(simulated_case_c):
    """The same check on the excerpt kept in the repository: runs on every clone."""
    excerpt = np.loadtxt(TEST_DATA / "paper_case_c_every50.csv", delimiter=",", comments="#")
    assert excerpt.shape == (21, 15)
    _check_against_authors(simulated_case_c, excerpt)


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
    run = simulate_case(case, vehicle="quad6dof", duration=12.0)
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

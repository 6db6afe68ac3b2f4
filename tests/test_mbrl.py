"""Model-based RL: the multi-seed experiment, its statistics, resuming, Ray, ensembles."""

import dataclasses
import json

import gymnasium as gym
import numpy as np
import pytest

from agents.mbrl import MBRLConfig, interval, run_experiment, run_job, steps_to_reach, summarize
from agents.parallel import ray_available, run_jobs
from identification.experiments.truth import model_from_truth
from identification.surrogate import EnsembleRhs, make_ensemble_surrogate

TINY = MBRLConfig(
    iterations=2, initial_real_steps=300, real_steps_per_iteration=200,
    model_steps_per_iteration=256, baseline_steps=512, baseline_evals=2, eval_episodes=1,
)  # fmt: skip


def test_interval_is_a_student_t_interval_of_the_logs():
    result = interval([10.0, 40.0], log=True)
    assert result["mean"] == pytest.approx(20.0)  # geometric mean
    half = 12.7062047 * np.std(np.log([10, 40]), ddof=1) / np.sqrt(2)  # t(0.975, 1 dof)
    assert result["low"] == pytest.approx(20.0 * np.exp(-half), rel=1e-6)
    assert result["high"] == pytest.approx(20.0 * np.exp(half), rel=1e-6)
    assert interval([3.0])["low"] is None and interval([])["mean"] is None


def test_sample_efficiency_counts_steps_to_95_percent_of_the_model_free_final_return():
    free = [{"real_steps": s, "return_mean": r} for s, r in [(1000, 10), (2000, 96), (3000, 100)]]
    sindy = [{"real_steps": s, "return_mean": r} for s, r in [(100, 50), (200, 95.5)]]
    missed = [{"real_steps": 100, "return_mean": 50}]
    assert steps_to_reach(free, 95.0) == 2000 and steps_to_reach(missed, 95.0) is None
    runs = {
        "model_free": {0: {"curve": free}, 1: {"curve": free}},
        "sindy": {0: {"curve": sindy}, 1: {"curve": missed}},
    }
    summary = summarize(runs, [0, 1])
    assert summary["seeds"][0]["ratio"] == pytest.approx(10.0)  # 2000 / 200
    assert summary["seeds"][0]["ratio_to_budget"] == pytest.approx(15.0)  # 3000 / 200
    assert summary["seeds"][1]["ratio"] is None
    assert (summary["reached"], summary["missed"]) == (1, 1)


def test_experiment_runs_saves_each_job_and_resumes(tmp_path):
    messages = []
    first = run_experiment(TINY, tmp_path, seeds=2, echo=messages.append)
    assert messages[0].startswith("4 jobs to run")
    saved = json.loads((tmp_path / "mbrl.json").read_text())
    assert set(saved["runs"]) == {"sindy", "model_free"}
    assert len(saved["runs"]["sindy"]["0"]["curve"]) == TINY.iterations
    real = [p["real_steps"] for p in saved["runs"]["sindy"]["0"]["curve"]]
    assert real[0] >= TINY.initial_real_steps and real[1] >= real[0] + 200
    assert (tmp_path / "mbrl.png").stat().st_size > 0
    # the loop's last surrogate and agent are kept, as the baseline's agent is
    kept = next(tmp_path.rglob("sindy_seed0"))
    from identification.model import load_model

    assert load_model(kept / "model.json").n_terms > 0 and (kept / "agent.zip").stat().st_size
    messages.clear()
    again = run_experiment(TINY, tmp_path, seeds=2, echo=messages.append)
    assert messages[0].startswith("0 jobs to run, 4 loaded")
    assert again["summary"] == json.loads(json.dumps(first["summary"]))
    # the first session's jobs and time stay on record (a resume wrote 0 jobs in ~0 s)
    assert again["run"]["jobs"] == first["run"]["jobs"] == 4 and len(again["sessions"]) == 2
    assert again["run"]["wall_seconds"] >= first["run"]["wall_seconds"] > 0
    with pytest.raises(ValueError, match=r"another configuration \(.*iterations: \d+ there, 3"):
        run_experiment(MBRLConfig(iterations=3), tmp_path, seeds=2)
    # one seed fewer is the same experiment: its jobs are loaded (a trial could not extend
    # or narrow an experiment)
    messages.clear()
    run_experiment(TINY, tmp_path, seeds=1, echo=messages.append)
    assert messages[0].startswith("0 jobs to run, 2 loaded")


@pytest.mark.skipif(not ray_available(), reason="Ray (the optional extra) is not installed")
def test_ray_gives_the_same_results_as_in_process(tmp_path):
    config = dataclasses.replace(TINY, iterations=1)
    args = [("sindy", config, seed, str(tmp_path)) for seed in (0, 1)]
    in_process = run_jobs(run_job, args)
    on_ray = run_jobs(run_job, args, workers=2)
    assert on_ray == in_process
    assert in_process[0] != in_process[1]  # the seeds matter


def test_jobs_validate_workers():
    with pytest.raises(ValueError, match="workers"):
        run_jobs(run_job, [], workers=0)


def test_ensemble_median_and_disagreement_truncation():
    exact = model_from_truth("planar")
    biased = model_from_truth("planar")
    biased.coefficients = biased.coefficients * 1.5
    ensemble = EnsembleRhs([exact, exact, biased])
    np.testing.assert_array_equal(ensemble.median_model().coefficients, exact.coefficients)
    x = np.zeros((3, 6))
    u = np.tile([2.0, 0.01], (3, 1))
    np.testing.assert_allclose(ensemble(x, u)[2], 1.5 * exact.rhs(x[0], u[0]))

    agree = make_ensemble_surrogate([exact, exact], "PlanarQuad-v0", threshold=1e-9)
    dispute = make_ensemble_surrogate([exact, biased], "PlanarQuad-v0", threshold=1e-6)
    for env, should_truncate in ((agree, False), (dispute, True)):
        env.reset(seed=0)
        _, _, terminated, truncated, info = env.step(np.array([2.0, 0.01]))
        assert truncated is should_truncate and not terminated
        assert (info["disagreement"] > 1e-6) is should_truncate
    sample = make_ensemble_surrogate([exact, biased], "PlanarQuad-v0", mode="sample")
    drawn = set()
    for seed in range(8):
        sample.reset(seed=seed)
        drawn.add(sample.member_rhs.index)
    assert drawn == {0, 1}
    with pytest.raises(ValueError, match="mode"):
        make_ensemble_surrogate([exact], "PlanarQuad-v0", mode="mean")
    assert isinstance(gym.wrappers.TimeLimit(agree, 10), gym.Wrapper)


def test_identify_bags_an_ensemble_around_the_selected_model():
    from agents.mbrl import _collect, identify
    from agents.policies import OrnsteinUhlenbeckPolicy
    from identification.libraries import default_library

    config = dataclasses.replace(TINY, ensemble=3)
    env = gym.make(config.env_id, **config.truth_kwargs)
    data = _collect(config, OrnsteinUhlenbeckPolicy(env, 0), 600, 0)
    models = identify(data, default_library("planar"), config, seed=0)
    assert len(models) == 3
    assert {tuple(m.feature_names) for m in models} == {tuple(models[0].feature_names)}
    assert "selection" in models[0].meta  # member 0 is the data-alone selection
    truth = model_from_truth("planar", models[0].feature_names)
    np.testing.assert_allclose(models[0].coefficients, truth.coefficients, rtol=1e-6, atol=1e-6)


def test_cli_effects_act_on_the_ground_truth_only(tmp_path):
    from typer.testing import CliRunner

    from quad_sindy.cli import app

    runner = CliRunner()
    bad = runner.invoke(app, ["mbrl", "--effects", "drag,bogus", "--out", str(tmp_path / "a")])
    assert bad.exit_code == 2 and "unknown effect 'bogus'" in bad.output
    assert len(bad.output.strip().splitlines()) == 1
    config = dataclasses.replace(TINY, env_options={"effects": ["drag"]})
    assert config.truth_kwargs["effects"] == ["drag"] and "effects" not in config.surrogate_kwargs
    # the vehicle (its action limits and trim) is the surrogate's too; the effects are not
    other = dataclasses.replace(TINY, env_options={"effects": ["drag"], "params": {"mass": "0.5"}})
    assert other.surrogate_kwargs["params"] == {"mass": "0.5"}
    assert "effects" not in other.surrogate_kwargs
    truth = gym.make("PlanarQuad-v0", **config.truth_kwargs)
    assert truth.unwrapped.effects.drag


def test_a_sindy_job_is_reproducible_from_its_seed(tmp_path):
    """Every surrogate env of the loop is seeded (a refitted model's new env included), so one
    seed gives the same learning curve twice, as Ray and in-process runs must."""
    config = dataclasses.replace(TINY, task="figure8", model_steps_per_iteration=2048)
    first = run_job("sindy", config, 3, str(tmp_path))
    assert run_job("sindy", config, 3, str(tmp_path)) == first


def test_configurations_compare_as_values():
    from agents.train import canonical

    assert canonical({"params": {"Ixx": "4e-3"}}) == canonical({"params": {"Ixx": 0.004}})
    assert canonical({"task": "hover"}) != canonical({"task": "figure8"})


def test_the_loop_can_identify_from_what_a_real_log_holds(tmp_path):
    """``data="measured"``: the loop's real rollouts record the sensors' state and the
    commands (with the truth's sensor bias and delay), and the loop runs on them."""
    from agents.mbrl import _collect
    from agents.policies import OrnsteinUhlenbeckPolicy

    config = dataclasses.replace(TINY, data="measured", env_options={"effects": ["sensor"]})
    policy = OrnsteinUhlenbeckPolicy(gym.make("PlanarQuad-v0", **config.truth_kwargs), 0)
    logged = _collect(config, policy, 100, 0)
    assert {t.meta["record"] for t in logged} == {"measured"}
    np.testing.assert_array_equal(logged[0].x[0], logged[0].x[1])  # the delay repeats it
    assert not np.allclose(logged[0].x[1], logged[0].x[2])
    result = run_job("sindy", config, 0, str(tmp_path))
    assert len(result["curve"]) == TINY.iterations
    with pytest.raises(ValueError, match="unknown data 'sensors'"):
        MBRLConfig(data="sensors")


def test_the_loop_records_the_surrogates_variables_when_the_truth_has_rotor_lag():
    """Rollouts of an env with rotor dynamics record the rotor states by default; the loop's
    surrogate steps the rigid body under the collective input, so it records that."""
    from agents.mbrl import _collect
    from agents.policies import OrnsteinUhlenbeckPolicy
    from identification.rollouts import collect_rollouts

    config = dataclasses.replace(TINY, env_options={"effects": ["rotor_dynamics"]})
    policy = OrnsteinUhlenbeckPolicy(gym.make("PlanarQuad-v0", **config.truth_kwargs), 0)
    logged = _collect(config, policy, 50, 0)
    assert logged[0].input_names == ("u1", "u2") and "T1" not in logged[0].state_names
    default = collect_rollouts("PlanarQuad-v0", policy, 1, max_steps=20,
                               env_kwargs=config.truth_kwargs)[0]  # fmt: skip
    assert default.input_names == ("Tc1", "Tc2") and default.state_names[-1] == "T2"
    with pytest.raises(ValueError, match="rotor_states=True needs an env with rotor dynamics"):
        collect_rollouts("PlanarQuad-v0", policy, 1, max_steps=5, rotor_states=True)


@pytest.mark.parametrize(
    "args,fragments",
    [
        (["--env", "CartPole-v1"], ["CartPole-v1 does not take the task's options"]),
        (["--env", "Foo-v0"], ["--env Foo-v0", "doesn't exist"]),
        (["--workers", "0"], ["--workers must be a positive integer, got 0"]),
        (["--disagreement", "nan"], ["--disagreement must be a finite number", "nan"]),
        (["--disagreement", "inf"], ["--disagreement must be a finite number", "inf"]),
    ],
)
def test_cli_refuses_bad_options_before_writing_its_configuration(
    monkeypatch, capsys, tmp_path, args, fragments
):
    """A failed start left config.json (a traceback for CartPole-v1), and the folder then
    refused the next, valid run as "another configuration"; NaN was stored as "never"."""
    from tests.test_cli import assert_one_line_error, run_cli

    out = tmp_path / "m"
    code, _, err = run_cli(monkeypatch, capsys, "mbrl", "--out", str(out), "--seeds", "1", *args)
    assert_one_line_error(code, err, *fragments)
    assert not out.exists()


def test_experiment_checks_workers_and_disagreement_before_writing(tmp_path):
    with pytest.raises(ValueError, match="workers must be a positive integer"):
        run_experiment(TINY, tmp_path / "w", seeds=1, workers=0)
    assert not (tmp_path / "w").exists()
    if not ray_available():  # parallel runs without Ray: refused before anything is written
        with pytest.raises(ValueError, match="parallel runs need Ray"):
            run_experiment(TINY, tmp_path / "r", seeds=1, workers=2)
        assert not (tmp_path / "r").exists()
    for value in (float("nan"), float("inf"), -1.0):
        with pytest.raises(ValueError, match="disagreement must be a finite number"):
            dataclasses.replace(TINY, disagreement=value)


RECORD = "sindy_seed0.json is not a finished run record"
CONFIG = "config.json is not an experiment configuration"


@pytest.mark.parametrize(
    "name,text,problem",
    [
        ("runs/sindy_seed0.json", "{}", rf"{RECORD} \(no 'curve'\)"),
        ("runs/sindy_seed0.json", "", rf"{RECORD} \(it is empty\)"),
        ("runs/sindy_seed0.json", "[1, 2]", rf"{RECORD} \(no 'curve'\)"),
        ("runs/model_free_seed0.json", '{"curve": [{"real_steps": 1}]}', "without the numbers"),
        ("config.json", "[1, 2]", rf"{CONFIG} \(not a JSON object\)"),
        ("config.json", '{"env_id": ', rf"{CONFIG} \(not JSON"),
    ],
)
def test_a_malformed_resume_file_is_named_with_what_to_do(tmp_path, name, text, problem):
    """Such files gave KeyError/TypeError tracebacks or a bare JSON decoder message."""
    from quad_envs.fileio import write_json

    settings = {**dataclasses.asdict(TINY), "seeds": [0]}
    write_json(tmp_path / "config.json", settings)
    curve = [{"real_steps": 100, "return_mean": 1.0, "return_std": 0.0}]
    for method in ("sindy", "model_free"):
        write_json(tmp_path / "runs" / f"{method}_seed0.json", {"seed": 0, "curve": curve})
    (tmp_path / name).write_text(text)
    fix = "use a new --out" if name == "config.json" else "remove it to rerun that job"
    with pytest.raises(ValueError, match=problem) as error:
        run_experiment(TINY, tmp_path, seeds=1, echo=lambda s: None)
    assert str(error.value).endswith(fix) and "\n" not in str(error.value)
    assert (tmp_path / name).read_text() == text  # nothing was overwritten

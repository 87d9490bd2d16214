"""Every invalid scene is refused at construction with a message naming the parameter."""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import sliders
from conftest import run
from sliders import Scene, SceneError
from sliders.scene import DEFAULT_MODE, SPEED_MODES, max_time_step

BAD = [
    (dict(n_sliders=0), r"n_sliders=0 is out of range: allowed \[1, \+inf\)"),
    (dict(n_sliders=2.5), r"n_sliders=2.5 must be an integer"),
    (dict(mu_d=0.6), r"mu_s_mean=0.6 must exceed mu_d=0.6"),
    (dict(mu_d=0.7), r"must exceed mu_d=0.7"),
    (dict(sigma_mu=-0.01), r"sigma_mu=-0.01 is out of range: allowed \[0, \+inf\)"),
    (dict(dt=0.0), r"dt=0.0 is out of range: allowed \(0, "),
    (dict(dt=-1e-3), r"dt=-0.001 is out of range"),
    (dict(dt=0.5), r"dt=0.5 is out of range.*fastest spring period"),
    (dict(xi=100.0, dt=0.03), r"dt=0.03 is out of range.*fastest spring period"),
    (dict(xi=-0.001), r"xi=-0.001 is out of range: allowed \[0, \+inf\)"),
    (dict(xi=math.nan), r"xi=nan must be finite"),
    (dict(mu_d=math.inf), r"mu_d=inf must be finite"),
    (dict(spring_length=-math.inf), r"spring_length=-inf must be finite"),
    (dict(mu_s_mean=math.nan), r"mu_s_mean=nan must be finite"),
    (dict(ends="periodic"), r"ends='periodic' must be one of \('free', 'walls'\)"),
    (dict(record="everything"), r"record='everything' must be one of"),
    (dict(seed=-1), r"seed=-1 is out of range"),
    (dict(refine_tol=1e-2), r"refine_tol=0.01 is out of range"),
    # below what double precision resolves at dt = 1e-3 (ulp 2.2e-19): the bisection never ended
    (dict(refine_tol=1e-20), r"refine_tol=1e-20 is out of range: allowed \[8.67361738e-19, 0.001\] "
                             r"\(at least 4 ulps of dt"),
    (dict(dt=1e-4, refine_tol=5e-20), r"refine_tol=5e-20 is out of range: allowed \[5.421010862e-20, 0.0001\]"),
    (dict(max_event_duration=1e13), r"max_event_duration=10000000000000.0 tau is out of range: allowed up "
                                    r"to about 1.13e\+12 tau at dt=0.001"),
    (dict(n_sliders=True), r"n_sliders=True must be an integer"),
    (dict(xi=np.bool_(False)), r"xi=np.False_ must be a real number"),
    (dict(max_event_duration=0.01), r"max_event_duration=0.01 tau must be at least 100 time steps"),
    (dict(alpha_max=2.0), r"alpha_max=2.0 is out of range"),
    (dict(output="/nonexistent-dir/run.h5"), r"output='/nonexistent-dir/run.h5': directory '/nonexistent-dir' does not exist"),
    (dict(output="/"), r"output='/' is a directory"),
]


@pytest.mark.parametrize("changes, message", BAD, ids=[str(c) for c, _ in BAD])
def test_bad_scene_is_refused_with_its_message(changes, message):
    with pytest.raises(SceneError, match=message):
        Scene(**changes)


def test_unwritable_location_is_refused(tmp_path):
    # /proc refuses new files even for root; a directory path cannot be a file either
    with pytest.raises(SceneError, match=r"output='/proc/run.h5' cannot be created in '/proc'"):
        Scene(output="/proc/run.h5")
    target = tmp_path / "run.h5"
    Scene(output=str(target))
    assert not target.exists()  # the check leaves nothing behind


def test_time_step_limit_follows_the_stiffness():
    assert max_time_step(0.0) == pytest.approx(2 * math.pi / 2 / 30)
    assert max_time_step(100.0) < max_time_step(1.0) < max_time_step(0.0)
    Scene(xi=100.0, dt=max_time_step(100.0))  # the limit itself is accepted


def test_speed_mode_gives_the_integrator_settings_unless_given():
    for mode, settings in SPEED_MODES.items():
        scene = Scene(mode=mode)
        assert {k: getattr(scene, k) for k in settings} == settings
    assert Scene().mode == DEFAULT_MODE and Scene().dt == SPEED_MODES[DEFAULT_MODE]["dt"]
    explicit = Scene(mode="explore", dt=5e-3)
    assert explicit.dt == 5e-3 and explicit.refine_tol == SPEED_MODES["explore"]["refine_tol"]
    # a new mode through replace brings its own settings, except those given with it
    assert explicit.replace(mode="reference").dt == SPEED_MODES["reference"]["dt"]
    assert explicit.replace(mode="reference", dt=2e-4).dt == 2e-4
    assert Scene.from_dict(explicit.to_dict()) == explicit


def test_speed_mode_errors_name_the_mode():
    with pytest.raises(SceneError, match=r"mode='fast' must be one of \('sketch'"):
        Scene(mode="fast")
    # explore's dt = 1e-2 is beyond a thirtieth of the fastest period for xi = 1e4
    with pytest.raises(SceneError, match=r"dt=0.01 is out of range.*comes from mode='explore': "
                                         r"give dt explicitly"):
        Scene(mode="explore", xi=1e4)


def test_speed_modes_are_ordered_in_accuracy():
    """Against the reference mode, the event angles of a deterministic N = 10
    scene converge at order 2 through the modes (measured: 5.6e-5, 5.0e-6,
    5.5e-7 for dt = 1e-2, 3e-3, 1e-3), each mode on the same event sequence."""
    base = Scene(n_sliders=10, seed=1, record="summary", max_events=30)
    ref = sliders.tilt(base.replace(mode="reference"))
    errors = {}
    for mode in ("explore", "statistics", "trajectory"):
        run = sliders.tilt(base.replace(mode=mode))
        assert run.n_events == ref.n_events > 15
        errors[mode] = np.abs(run.events["drive"] - ref.events["drive"]).max()
    assert errors["trajectory"] < 2e-6
    ratio = (SPEED_MODES["explore"]["dt"] / SPEED_MODES["trajectory"]["dt"]) ** 2
    assert errors["explore"] / errors["trajectory"] > 0.3 * ratio
    assert errors["explore"] > errors["statistics"] > errors["trajectory"]


def test_command_line_mode_with_a_scene_file(tmp_path):
    """A scene file's mode and an explicit option combine like the constructor."""
    import argparse

    from sliders.runs.cli import add_scene_arguments, scene_from_args

    path = tmp_path / "s.toml"
    path.write_text('[scene]\nn_sliders = 20\nmode = "statistics"\n')
    parser = argparse.ArgumentParser()
    add_scene_arguments(parser)
    scene = scene_from_args(parser.parse_args(["--scene", str(path)]))
    assert scene.mode == "statistics" and scene.dt == SPEED_MODES["statistics"]["dt"]
    scene = scene_from_args(parser.parse_args(["--scene", str(path), "--mode", "explore"]))
    assert scene.dt == SPEED_MODES["explore"]["dt"] and scene.n_sliders == 20
    scene = scene_from_args(parser.parse_args(["--scene", str(path), "--dt", "2e-3"]))
    assert scene.mode == "statistics" and scene.dt == 2e-3


def test_unknown_backend_is_refused():
    with pytest.raises(SceneError, match=r"backend='cuda' must be one of \('fortran', 'numpy'\)"):
        sliders.tilt(Scene(n_sliders=2), backend="cuda")


def test_unknown_key_in_scene_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("n_sliders = 10\nfrobnicate = 3\n")
    with pytest.raises(SceneError, match=r"unknown scene key\(s\) \['frobnicate'\]"):
        Scene.from_toml(path)


@pytest.mark.parametrize("text, message", [
    # a key above [scene] belongs to no table: it was silently ignored
    ("n_sliders = 10\n[scene]\nxi = 0.001\n",
     r"key 'n_sliders' stands outside the \[scene\] table"),
    ("[scene]\nn_sliders = 10\n[output]\npath = 'x'\n", r"key 'output' stands outside"),
    ("[scene]\nn_sliders = 10\n[scene.integrator]\ndt = 1e-3\n",
     r"table 'integrator' is not a scene key"),
    ("[scene]\nn_slider = 10\n", r"unknown scene key\(s\) \['n_slider'\] \(did you mean 'n_sliders'\?\)"),
    ("[sliders]\nn_sliders = 10\n", r"table 'sliders' is not a scene key \(did you mean 'n_sliders'\?\)"),
])
def test_scene_file_refuses_keys_and_tables_it_does_not_know(tmp_path, text, message):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(SceneError, match=message):
        Scene.from_toml(path)


def test_scene_file_key_above_scene_table_on_the_command_line(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("n_sliders = 10\n[scene]\nxi = 0.001\n")
    proc = _cli("tilt", "--scene", str(path), "--out", str(tmp_path / "o.h5"))
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "'n_sliders'" in proc.stderr


def test_numpy_scalars_are_accepted_and_saved_as_plain_numbers(tmp_path):
    scene = Scene(n_sliders=np.int64(10), seed=np.uint32(3), xi=np.float32(0.001),
                  dt=np.float64(2e-3), max_events=np.int32(1000), mu_d=np.float16(0.5),
                  ends=np.str_("free"))
    assert scene == Scene(n_sliders=10, seed=3, xi=0.001, dt=2e-3, max_events=1000, mu_d=0.5)
    plain = scene.to_dict()
    assert type(plain["n_sliders"]) is int and type(plain["seed"]) is int
    assert type(plain["xi"]) is float and plain["xi"] == 0.001  # what was written, not 0.0010000000474974513
    assert type(plain["ends"]) is str
    import json

    assert Scene.from_dict(json.loads(json.dumps(plain))) == scene
    out = tmp_path / "r.h5"
    sliders.tilt(scene.replace(max_events=5)).save(out)
    assert sliders.Result.load(out).scene == scene.replace(max_events=5)


def test_scene_beyond_available_memory_is_refused_up_front(monkeypatch):
    from sliders import scene as scene_module

    huge = Scene(n_sliders=10**10)
    assert huge.memory_estimate() > 4e12
    with pytest.raises(SceneError, match=r"n_sliders=10000000000 .* needs about .* GB, more than "
                                         r"the .* GB available"):
        sliders.tilt(huge)
    # the estimate follows the record mode and max_events
    big = Scene(n_sliders=10**6)
    assert big.replace(record="summary").memory_estimate() < big.memory_estimate()
    assert big.replace(max_events=10).memory_estimate() < big.memory_estimate()
    monkeypatch.setattr(scene_module, "available_memory", lambda: 1000)
    with pytest.raises(SceneError, match="available"):
        scene_module.check_memory(Scene(n_sliders=10))


def test_memory_refusal_on_the_command_line(tmp_path):
    proc = _cli("tilt", "--n-sliders", str(10**10), "--out", str(tmp_path / "o.h5"))
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "GB available" in proc.stderr


def test_scene_round_trips_through_dict():
    scene = Scene(n_sliders=7, xi=0.001, seed=12, ends="walls")
    assert Scene.from_dict(scene.to_dict()) == scene


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "sliders", *args], capture_output=True, text=True,
                          timeout=120, cwd=cwd)


@pytest.mark.parametrize("args, message", [
    (["--n-sliders", "0"], "n_sliders=0 is out of range"),
    (["--mu-d", "0.7"], "must exceed mu_d=0.7"),
    (["--dt", "nan"], "dt=nan must be finite"),
    (["--sigma-mu", "-1"], "sigma_mu=-1.0 is out of range"),
    (["--xi", "-1"], "xi=-1.0 is out of range"),
    (["--out", "/nonexistent-dir/x.h5"], "directory '/nonexistent-dir' does not exist"),
])
def test_command_line_refuses_bad_input_without_traceback(args, message, tmp_path):
    argv = ["tilt", "--out", str(tmp_path / "run.h5"), *args]
    proc = _cli(*argv)
    assert proc.returncode != 0
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_command_line_backend_choice_is_checked(tmp_path):
    proc = _cli("tilt", "--backend", "cuda", "--out", str(tmp_path / "run.h5"))
    assert proc.returncode != 0 and "invalid choice: 'cuda'" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_command_line_never_overwrites_silently(tmp_path):
    out = tmp_path / "run.h5"
    out.write_text("precious")
    proc = _cli("tilt", "--n-sliders", "2", "--out", str(out))
    assert proc.returncode != 0 and "exists; pass --overwrite" in proc.stderr
    assert out.read_text() == "precious"


def test_command_line_runs_and_writes_a_loadable_file(tmp_path):
    out = tmp_path / "run.h5"
    # the reference on a short chain at a coarser step (under a second), and --dt reaches the scene
    proc = _cli("tilt", "--n-sliders", "4", "--seed", "4", "--dt", "0.004", "--backend", "numpy",
                "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "avalanche: alpha_c=" in proc.stdout
    result = sliders.Result.load(out)
    direct = run(Scene(n_sliders=4, seed=4, dt=0.004), "numpy")
    assert result.alpha_c == direct.alpha_c
    assert (result.alpha == direct.alpha).all()
    assert result.final_event == direct.final_event and result.final_event["n_steps"] > 0


def assert_identical(a, b, where="result"):
    """Every field of two results (dataclasses, dicts, arrays, numbers) the same to the last
    bit and of the same type (NaN equal to NaN)."""
    assert type(a) is type(b), (where, type(a), type(b))
    if dataclasses.is_dataclass(a) and not isinstance(a, Scene):
        for f in dataclasses.fields(a):
            assert_identical(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            assert_identical(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype, (where, a.dtype, b.dtype)
        np.testing.assert_array_equal(a, b, err_msg=where, strict=True)
    elif isinstance(a, float):
        assert a == b or (math.isnan(a) and math.isnan(b)), (where, a, b)
    else:
        assert a == b, (where, a, b)


@pytest.mark.parametrize("scene", [
    Scene(n_sliders=10, seed=3),
    Scene(n_sliders=10, seed=3, record="summary", max_events=12),
    Scene(n_sliders=6, seed=2, loading="pushed_end", incline=0.2, ends="walls"),
], ids=["tilt", "summary", "pushed_end"])
def test_a_saved_run_loads_as_the_same_run_to_the_last_bit(scene, tmp_path):
    """Every field written (states, drives, events, displacements, works) reads back as it was:
    a run continued from a file starts from the very state it stopped in."""
    result = sliders.tilt(scene)
    result.save(tmp_path / "run.h5")
    loaded = sliders.Result.load(tmp_path / "run.h5")
    assert_identical(result, loaded)
    assert loaded.scene == scene

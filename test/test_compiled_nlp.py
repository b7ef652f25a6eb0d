"""The compile cache of NLP functions: key, build, use, and the fallbacks that keep a planner working.

Every compile here is of a 2-interval NLP (under a second with gcc); the default NLP is never compiled
in tests, so CI time does not grow.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.block_ldl import block_ldl_library_path
from helireach_ros.core.ocp.compiled_nlp import CodegenSettings, library_path, nlp_key
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.planning.planner import LandingPlanner
from helireach_ros.core.units import FT, KT

pytestmark = [pytest.mark.build]

TINY = PlannerSettings(intervals=6, degree=2)  # flyable, coarse: fast to compile (2-4 intervals are infeasible)


@pytest.fixture(scope="module")
def uh60():
    return load_airframe("uh60a_class")


def _nlp(planner: LandingPlanner) -> dict:
    transcription = planner.transcription
    return {"x": transcription.decision, "p": transcription.parameters, "f": transcription.objective,
            "g": transcription.constraints}  # fmt: skip


def test_key_is_stable_and_changes_with_the_nlp_and_the_compiler(uh60, tmp_path):
    off = CodegenSettings(mode="off", cache_dir=str(tmp_path))
    tiny, again = LandingPlanner(uh60, TINY, off), LandingPlanner(uh60, TINY, off)
    other_mesh = LandingPlanner(uh60, TINY.replace(intervals=3), off)
    other_weight = LandingPlanner(uh60, TINY.replace(smoothness_weight=2e-3), off)
    key = nlp_key(_nlp(tiny), off)
    assert len(key) == 64 and nlp_key(_nlp(again), off) == key  # a rebuilt NLP finds its library
    assert nlp_key(_nlp(other_mesh), off) != key
    assert nlp_key(_nlp(other_weight), off) != key
    assert nlp_key(_nlp(tiny), CodegenSettings(mode="off", flags=("-O2",))) != key
    assert nlp_key(_nlp(tiny), CodegenSettings(mode="off", compiler="clang")) != key


def test_cached_mode_without_a_library_uses_the_plain_functions_and_says_so(uh60, tmp_path):
    planner = LandingPlanner(uh60, TINY, CodegenSettings(mode="cached", cache_dir=str(tmp_path)))
    assert "plain" in planner.nlp_functions and "no compiled library" in planner.nlp_functions
    assert not list(tmp_path.glob("landing_nlp*"))  # never compiles the NLP on its own (block LDL^T: test_block_ldl)
    assert planner.plan(initial_state_after_failure(uh60, 500 * FT, 75 * KT)).solver.iterations > 0


def test_a_missing_compiler_falls_back_to_the_plain_functions(uh60, tmp_path, caplog):
    codegen = CodegenSettings(mode="build", cache_dir=str(tmp_path), compiler=str(tmp_path / "no-such-cc"))
    planner = LandingPlanner(uh60, TINY, codegen)
    assert "build failed" in planner.nlp_functions and "no-such-cc" in planner.nlp_functions
    assert "code generation failed" in caplog.text
    assert not library_path(_nlp(planner), codegen).exists()
    assert planner.linear_solver.startswith("MUMPS (block LDL^T unavailable") and "no-such-cc" in planner.linear_solver
    plain = LandingPlanner(uh60, TINY, CodegenSettings(mode="off", linear_solver="mumps"))
    state = initial_state_after_failure(uh60, 500 * FT, 75 * KT)
    assert planner.plan(state).value == plain.plan(state).value


def test_a_failing_compiler_falls_back_too(uh60, tmp_path):
    planner = LandingPlanner(uh60, TINY, CodegenSettings(mode="build", cache_dir=str(tmp_path), flags=("-Wbogus-x",)))
    assert "build failed" in planner.nlp_functions and "-Wbogus-x" in planner.nlp_functions


@pytest.mark.skipif(shutil.which("gcc") is None, reason="no C compiler on this machine")
def test_compiled_functions_give_the_same_plans_and_a_damaged_library_is_not_loaded(uh60, tmp_path):
    codegen = CodegenSettings(mode="build", cache_dir=str(tmp_path))
    compiled = LandingPlanner(uh60, TINY, codegen)
    assert compiled.nlp_functions.startswith("compiled library")
    path = library_path(_nlp(compiled), codegen)
    assert path.is_file()
    block_ldl = block_ldl_library_path(codegen)
    libraries = sorted([path.name, path.name + ".sha256", block_ldl.name, block_ldl.name + ".sha256"])
    assert sorted(p.name for p in tmp_path.iterdir()) == libraries  # no build leftovers
    reused = LandingPlanner(uh60, TINY, CodegenSettings(mode="cached", cache_dir=str(tmp_path)))
    assert reused.nlp_functions == compiled.nlp_functions
    plain = LandingPlanner(uh60, TINY, CodegenSettings(mode="off"))
    for height_ft, speed_kt in ((500, 75), (150, 0)):
        state = initial_state_after_failure(uh60, height_ft * FT, speed_kt * KT)
        first, second = compiled.plan(state), plain.plan(state)
        assert first.status == second.status and first.solver.iterations == second.solver.iterations
        assert first.value == pytest.approx(second.value, abs=1e-9)
        assert np.allclose(first.warm_start.primal, second.warm_start.primal, atol=1e-8)
        warm = compiled.plan(state, warm_start=second.warm_start)
        assert warm.solver.warm_started and warm.value == pytest.approx(second.value, abs=1e-6)
    # a truncated library under the right name (another folder: the good one stays mapped in this process)
    broken_cache = tmp_path / "broken"
    broken_cache.mkdir()
    (broken_cache / path.name).write_bytes(path.read_bytes()[:4096])  # loading this would crash the process
    shutil.copy(path.with_name(path.name + ".sha256"), broken_cache)
    broken = LandingPlanner(uh60, TINY, CodegenSettings(mode="cached", cache_dir=str(broken_cache)))
    assert "does not match its checksum" in broken.nlp_functions
    assert broken.plan(initial_state_after_failure(uh60, 500 * FT, 75 * KT)).value == pytest.approx(
        plain.plan(initial_state_after_failure(uh60, 500 * FT, 75 * KT)).value, abs=1e-9
    )


def test_bad_codegen_settings_are_refused():
    with pytest.raises(ValueError, match="mode"):
        CodegenSettings(mode="sometimes")
    with pytest.raises(ValueError, match="compiler"):
        CodegenSettings(compiler=" ")


def test_environment_selects_the_codegen_settings(monkeypatch, tmp_path):
    monkeypatch.setenv("HELIREACH_NLP_CODEGEN", "off")
    monkeypatch.setenv("HELIREACH_NLP_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "clang")
    monkeypatch.setenv("HELIREACH_NLP_CFLAGS", "-O2 -march=native")
    settings = CodegenSettings.from_environment()
    assert settings == CodegenSettings("off", str(tmp_path), "clang", ("-O2", "-march=native"))

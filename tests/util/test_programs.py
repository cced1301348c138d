"""Programs compiled ahead of time (:mod:`brdffit.util.programs`): the same answers as the
function they wrap, and a fresh process that finds a stored fit neither traces nor
compiles it again, and fits to the same bits."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from brdffit.util import programs
from brdffit.util.jax_config import CACHE_MAX_BYTES
from brdffit.util.programs import Program


class _Pair(eqx.Module):
    a: jax.Array
    b: jax.Array
    tag: str = eqx.field(static=True)


def _f(pair: _Pair, x: np.ndarray, power: int):
    return {"sum": pair.a + x**power, "out": _Pair(pair.b * 2.0, jnp.sum(x), pair.tag)}


def test_a_program_returns_what_its_function_returns_for_each_shape_and_static_value():
    p = Program(_f)
    pair = _Pair(jnp.arange(3.0), jnp.ones(2), "t")
    for x, power in ((np.linspace(0, 1, 3), 2), (np.linspace(0, 1, 3), 3), (np.ones(3), 2)):
        got, want = p(pair, x, power), _f(pair, x, power)
        assert jax.tree.structure(got) == jax.tree.structure(want)
        for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
            np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
    assert len(p._entries) == 2  # the shape and static value that repeat share a program


def test_without_the_persistent_cache_nothing_is_stored():
    assert jax.config.jax_compilation_cache_dir in (None, "")
    assert programs.store_folder() is None


def test_a_stored_program_that_cannot_run_is_removed_and_compiled_again(tmp_path, caplog):
    path = tmp_path / "race-0.pkl"
    path.write_bytes(b"an executable that loads")
    calls = []

    def loaded(*xs):
        calls.append("loaded")
        raise jax.errors.JaxRuntimeError("NOT_FOUND: Function fusion not found")

    def fallback(*xs):
        calls.append("fallback")
        return (sum(xs),)

    entry = programs._Entry(loaded)
    entry.call = programs._checked(entry, loaded, fallback, path)
    assert entry.call(1, 2) == (3,) and entry.call(3, 4) == (7,)
    assert calls == ["loaded", "fallback", "fallback"]  # tried once, then never again
    assert not path.exists() and "failed to run" in caplog.text


_SCRIPT = textwrap.dedent(
    """
    import json, pickle, sys
    import jax
    import brdffit
    from brdffit import fit, models, synthesize
    from brdffit.util import programs

    brdffit.enable_compilation_cache(sys.argv[1])
    compiled, read = [], []
    _compile = programs._compile
    def counting_compile(lowered):
        out = _compile(lowered)
        compiled.append(out[1])
        return out
    programs._compile = counting_compile
    _read = programs._read
    def counting_read(path, n_args):
        out = _read(path, n_args)
        read.append(out is not None)
        return out
    programs._read = counting_read
    # the smallest model with an affine and a nonlinear parameter runs every program of
    # a fit (starts screened and raced, covariance, losses) and compiles quickest
    m = models.get("oren_nayar")
    truth = {"rho": [0.5, 0.3, 0.2], "sigma": 0.3}
    data = synthesize(m, truth, stride=(9, 9, 9), noise_mult=0.03, seed=2)
    r = fit(m, data, "low_e2")
    stored = sorted(programs.store_folder().iterdir())
    print(json.dumps({
        "compiled": len(compiled), "fresh": sum(compiled), "read": sum(read),
        "max_size": jax.config.jax_compilation_cache_max_size,
        "loss": r.loss.hex(), "params": {k: v.tolist() for k, v in r.params.items()},
        "stderr": {k: v.tolist() for k, v in r.stderr.items()},
        "files": [p.name.split("-")[0] for p in stored],
        "kinds": [pickle.loads(p.read_bytes())[0] for p in stored],
    }))
    """
)


def _run(cache: Path) -> dict:
    env = dict(os.environ, BRDFFIT_JAX_CACHE=str(cache))
    out = subprocess.run(
        [sys.executable, "-c", _SCRIPT, str(cache)],
        capture_output=True, text=True, env=env, check=True, timeout=600,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_fresh_process_fits_from_stored_programs_to_the_same_bits(tmp_path):
    first = _run(tmp_path)
    # XLA compiled every program here, so each is stored as its executable
    assert first["compiled"] == first["fresh"] > 0 and first["read"] == 0
    assert set(first["kinds"]) == {programs.EXECUTABLE}
    # bounded, so JAX locks the folder: processes sharing it never read a half-written file
    assert first["max_size"] == CACHE_MAX_BYTES
    stored = set(first["files"])
    fit_programs = {"shading_geometry", "select_one", "race", "answer"}
    assert fit_programs <= stored, stored

    # the second process finds every program stored, and one of them damaged: that one
    # alone is compiled again; XLA's own cache answers it, and an executable from there
    # is stored as StableHLO (it does not serialise whole on the CPU)
    damaged = next(p for p in (tmp_path).rglob("race-*.pkl"))
    damaged.write_bytes(b"not a program")
    second = _run(tmp_path)
    assert second["compiled"] == 1 and second["fresh"] == 0, "an intact program was compiled"
    assert second["read"] == len(first["files"]) - 1
    assert second["files"] == first["files"]
    kinds = dict(zip(second["files"], second["kinds"], strict=True))
    assert kinds.pop("race") == programs.EXPORTED
    assert set(kinds.values()) == {programs.EXECUTABLE}

    # the third reads both kinds back and fits to the same bits as the first
    third = _run(tmp_path)
    assert third["compiled"] == 0 and third["read"] == len(first["files"])
    for run in (second, third):
        for key in ("loss", "params", "stderr"):
            assert run[key] == first[key], key

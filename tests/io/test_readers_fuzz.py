"""Random and mutated bytes to every reader: a typed BrdffitError or a valid result, never
another exception (issue 29). Few examples and small files: the suite stays fast."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from brdffit import (
    BrdffitError,
    Measurements,
    models,
    read_merl,
    read_nbrdf,
    read_table,
    synthesize,
    write_merl,
)
from brdffit.io.rgl_header import rgl_header

FUZZ = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,  # the same bytes every run: a failure is reproducible
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def _mutate(seed: bytes, edits: list[tuple[int, int]], cut: int | None) -> bytes:
    """``seed`` with bytes overwritten at (position, value) pairs, then cut to ``cut``."""
    b = bytearray(seed)
    for pos, val in edits:
        if b:
            b[pos % len(b)] = val
    return bytes(b[:cut] if cut is not None else b)


EDITS = st.lists(st.tuples(st.integers(0, 2**31), st.integers(0, 255)), max_size=12)
CUTS = st.none() | st.integers(0, 4096)


def _read_or_refuse(reader, path: Path):
    """Call ``reader(path)``: a BrdffitError is fine, any other exception fails the test."""
    try:
        return reader(path)
    except BrdffitError:
        return None


def _write(tmp: Path, name: str, data: bytes) -> Path:
    p = tmp / name
    p.write_bytes(data)
    return p


# --------------------------------------------------------------------------- seeds


def _csv_seed() -> bytes:
    data = synthesize(models.get("lambert"), {"kd": [0.2, 0.3, 0.4]}, grid="random", n=12)
    rows = np.concatenate([data.wi, data.wo, data.values], axis=1)
    buf = io.StringIO()
    np.savetxt(buf, rows, delimiter=",", fmt="%.6g", header="wi_x,wi_y,wi_z,wo_x,wo_y,wo_z,r,g,b",
               comments="")  # fmt: skip
    return buf.getvalue().encode()


def _npz_seed() -> bytes:
    data = synthesize(models.get("lambert"), {"kd": [0.2, 0.3, 0.4]}, grid="random", n=12)
    buf = io.BytesIO()
    np.savez(buf, wi=np.asarray(data.wi), wo=np.asarray(data.wo), rgb=np.asarray(data.values))
    return buf.getvalue()


CSV_SEED, NPZ_SEED = _csv_seed(), _npz_seed()


# --------------------------------------------------------------------------- tables


@FUZZ
@given(data=st.binary(max_size=512))
def test_random_bytes_to_the_table_readers(tmp_path, data):
    for name in ("t.csv", "t.npz"):
        r = _read_or_refuse(read_table, _write(tmp_path, name, data))
        assert r is None or isinstance(r, Measurements)


@FUZZ
@given(edits=EDITS, cut=CUTS)
def test_mutated_csv(tmp_path, edits, cut):
    r = _read_or_refuse(read_table, _write(tmp_path, "t.csv", _mutate(CSV_SEED, edits, cut)))
    assert r is None or isinstance(r, Measurements)


@FUZZ
@given(text=st.text(max_size=200))
def test_random_text_csv(tmp_path, text):
    path = tmp_path / "t.csv"
    path.write_text("wi_x,wi_y,wi_z,wo_x,wo_y,wo_z,r,g,b\n" + text, encoding="utf-8")
    r = _read_or_refuse(read_table, path)
    assert r is None or isinstance(r, Measurements)


@FUZZ
@given(edits=EDITS, cut=CUTS)
def test_mutated_npz(tmp_path, edits, cut):
    r = _read_or_refuse(read_table, _write(tmp_path, "t.npz", _mutate(NPZ_SEED, edits, cut)))
    assert r is None or isinstance(r, Measurements)


# --------------------------------------------------------------------------- MERL, .bsdf


@pytest.fixture(scope="module")
def merl_seed(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("fuzz") / "seed.binary"
    write_merl(path, synthesize(models.get("lambert"), {"kd": [0.2, 0.3, 0.4]}))
    return path.read_bytes()


@FUZZ
@given(data=st.binary(max_size=256))
def test_random_bytes_to_merl_and_bsdf_readers(tmp_path, data):
    assert _read_or_refuse(read_merl, _write(tmp_path, "x.binary", data)) is None
    assert _read_or_refuse(rgl_header, _write(tmp_path, "x.bsdf", data)) is None


@settings(FUZZ, max_examples=4)  # a MERL file is 35 MB: few examples
@given(
    edits=st.lists(
        st.tuples(st.integers(0, 2**31), st.sampled_from([0, 0x7F, 0xFF, 0xF0])), max_size=6
    ),
    cut=st.none() | st.integers(0, 64),
)
def test_mutated_merl(tmp_path, merl_seed, edits, cut):
    header = [(e[0] % 12, e[1]) for e in edits[:2]]  # one mutation in 3 hits the header
    data = _mutate(merl_seed, header + edits[2:], cut)
    r = _read_or_refuse(read_merl, _write(tmp_path, "x.binary", data))
    assert r is None or isinstance(r, Measurements)


def _tensor_seed() -> bytes:
    """A small tensor file with the fields of Mitsuba's ``measured`` format."""
    import struct

    fields = {
        "description": np.frombuffer(b"fuzz seed", np.uint8),
        "theta_i": np.linspace(0, 1.4, 3).astype(np.float32),
        "phi_i": np.zeros(1, np.float32),
        "ndf": np.ones((4, 4), np.float32),
        "sigma": np.ones((4, 4), np.float32),
        "vndf": np.ones((1, 3, 4, 4), np.float32),
        "luminance": np.ones((1, 3, 4, 4), np.float32),
        "jacobian": np.ones(1, np.uint8),
        "rgb": np.ones((1, 3, 3, 4, 4), np.float32),
    }
    codes = {np.dtype("u1"): 1, np.dtype("f4"): 10}
    head = b"tensor_file\0" + b"\x01\x00" + struct.pack("<I", len(fields))
    entries = [(name.encode(), a) for name, a in fields.items()]
    size = len(head) + sum(2 + len(n) + 11 + 8 * a.ndim for n, a in entries)
    body, parts = b"", []
    for n, a in entries:
        offset = size + len(body)
        parts.append(struct.pack("<H", len(n)) + n + struct.pack("<HBQ", a.ndim, codes[a.dtype],
                                                                 offset))  # fmt: skip
        parts.append(struct.pack(f"<{a.ndim}Q", *a.shape))
        body += a.tobytes()
    return head + b"".join(parts) + body


TENSOR_SEED = _tensor_seed()


def test_tensor_seed_is_read():
    # the seed is a valid header: the mutations below start from a file that is read
    assert rgl_header(_write_tmp("seed.bsdf", TENSOR_SEED)).resolution == (4, 4)


def _write_tmp(name: str, data: bytes) -> Path:
    import tempfile

    folder = Path(tempfile.mkdtemp())
    return _write(folder, name, data)


@FUZZ
@given(edits=EDITS, cut=CUTS)
def test_mutated_bsdf_header(tmp_path, edits, cut):
    data = _mutate(TENSOR_SEED, [(p % 300, v) for p, v in edits], cut)
    _read_or_refuse(rgl_header, _write(tmp_path, "x.bsdf", data))


# --------------------------------------------------------------------------- NBRDF


@pytest.fixture(scope="module")
def nbrdf_seed(tmp_path_factory) -> Path:
    pytest.importorskip("h5py")
    from tests.io.test_nbrdf import _architecture, _random_weights, _write_keras

    return _write_keras(
        tmp_path_factory.mktemp("nbrdf") / "toy", _random_weights(units=(4, 3)),
        _architecture(units=(4, 3)),
    )  # fmt: skip


@FUZZ
@given(edits=EDITS, cut=CUTS, which=st.sampled_from([".json", ".h5"]))
def test_mutated_nbrdf(tmp_path, nbrdf_seed, edits, cut, which):
    stem = tmp_path / "toy"
    for suffix in (".json", ".h5"):
        shutil.copy(nbrdf_seed.with_suffix(suffix), stem.with_suffix(suffix))
    target = stem.with_suffix(which)
    target.write_bytes(_mutate(target.read_bytes(), edits, cut))
    _read_or_refuse(read_nbrdf, stem)


@FUZZ
@given(
    doc=st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
        lambda kids: (
            st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids, max_size=4)
        ),
        max_leaves=12,
    )
)
def test_random_json_architecture(tmp_path, nbrdf_seed, doc):
    stem = tmp_path / "toy"
    shutil.copy(nbrdf_seed.with_suffix(".h5"), stem.with_suffix(".h5"))
    arch = json.loads(nbrdf_seed.with_suffix(".json").read_text())
    key = ["units", "activation", "batch_input_shape", "use_bias", "name"][len(str(doc)) % 5]
    arch["config"]["layers"][0]["config"][key] = doc  # one field replaced by random JSON
    if isinstance(doc, dict):
        arch["config"]["layers"][-1] = doc  # and the Lambda layer by random JSON
    stem.with_suffix(".json").write_text(json.dumps(arch))
    _read_or_refuse(read_nbrdf, stem)

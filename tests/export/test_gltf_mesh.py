"""The sphere every glTF export carries (:mod:`brdffit.export.gltf_mesh`), read back from the
written JSON alone by the rules of the glTF 2.0 specification (sections 3.5-3.7 and 5): a
scene that reaches the mesh, a buffer whose embedded bytes have the declared length,
views inside it and 4-byte aligned, accessors inside their views with POSITION's min and
max equal to the data, unit normals, indices in range and triangles counter-clockwise
seen from outside (the front face)."""

from __future__ import annotations

import base64
import json

import numpy as np

from brdffit.export import export
from tests.export.test_export import result

SIZES = {5126: 4, 5123: 2}
COMPONENTS = {"SCALAR": 1, "VEC3": 3}
DTYPES = {5126: np.float32, 5123: np.uint16}


def _read(doc: dict, k: int) -> np.ndarray:
    acc = doc["accessors"][k]
    view = doc["bufferViews"][acc["bufferView"]]
    blob = base64.b64decode(doc["buffers"][view["buffer"]]["uri"].split(",", 1)[1])
    n = acc["count"] * COMPONENTS[acc["type"]]
    start = view["byteOffset"] + acc.get("byteOffset", 0)
    assert start + n * SIZES[acc["componentType"]] <= view["byteOffset"] + view["byteLength"]
    data = np.frombuffer(blob, DTYPES[acc["componentType"]], n, start)
    return data.reshape(acc["count"], -1)


def test_every_gltf_export_holds_a_valid_sphere_with_the_material():
    e = export(result("walter[masking=height_correlated,diffuse=false,grey=ks]",
                      {"ks": 0.7, "f0": [0.9, 0.6, 0.3], "alpha": 0.2}), "gltf")  # fmt: skip
    doc = json.loads(e.files[".gltf"])
    (node,) = [doc["nodes"][i] for i in doc["scenes"][doc["scene"]]["nodes"]]
    (prim,) = doc["meshes"][node["mesh"]]["primitives"]
    assert prim["material"] == 0 and prim.get("mode", 4) == 4
    (buf,) = doc["buffers"]
    assert buf["uri"].startswith("data:application/octet-stream;base64,")
    assert len(base64.b64decode(buf["uri"].split(",", 1)[1])) == buf["byteLength"]
    for v in doc["bufferViews"]:
        assert v["byteOffset"] % 4 == 0 and v["byteOffset"] + v["byteLength"] <= buf["byteLength"]
    pos = _read(doc, prim["attributes"]["POSITION"])
    acc = doc["accessors"][prim["attributes"]["POSITION"]]
    np.testing.assert_array_equal(acc["min"], pos.min(axis=0))
    np.testing.assert_array_equal(acc["max"], pos.max(axis=0))
    normal = _read(doc, prim["attributes"]["NORMAL"])
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-6)
    assert sorted(prim["attributes"]) == ["NORMAL", "POSITION"]
    tri = _read(doc, prim["indices"]).reshape(-1, 3).astype(int)
    assert tri.max() < len(pos) and len(tri) > 1000
    a, b, c = (pos[tri[:, k]].astype(float) for k in range(3))
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c)
    assert (outward > 0).all()  # counter-clockwise seen from outside
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    assert abs(area - 4 * np.pi) < 0.05 * 4 * np.pi  # it is the unit sphere
    assert len(e.files[".gltf"]) < 150_000

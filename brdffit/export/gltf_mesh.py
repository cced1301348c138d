"""A unit sphere for a glTF document, so that a viewer opening the file shows its material.

A glTF file holding only ``materials`` is a valid asset that every viewer shows as an
empty scene. :func:`add_sphere` adds what a scene needs (glTF 2.0 specification,
sections 3.5 Scenes, 3.6 Buffers, 3.7 Meshes): one ``buffer`` embedded as a base64 data
URI (no second file to lose), ``bufferViews`` for the vertex attributes (target
ARRAY_BUFFER, 34962) and the indices (ELEMENT_ARRAY_BUFFER, 34963), ``accessors`` for
``POSITION`` (float VEC3, with the ``min`` and ``max`` the specification requires) and
``NORMAL`` (unit float VEC3), and unsigned-short triangle
indices (counter-clockwise seen from outside, the specification's front face), a
``mesh`` whose one primitive uses material 0, a ``node`` and the default ``scene``.
Y is up (glTF's convention). Every view is 4-byte aligned. No texture coordinates: the
material has no textures, and the Khronos validator reports an unused ``TEXCOORD_0``.
"""

from __future__ import annotations

import base64

import numpy as np

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
FLOAT = 5126
UNSIGNED_SHORT = 5123
TRIANGLES = 4


def sphere(n_lat: int = 24, n_lon: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """Unit latitude-longitude sphere: positions (V, 3) float32 (= normals) and triangle
    indices (T, 3), counter-clockwise seen from outside, Y up."""
    theta = np.linspace(0.0, np.pi, n_lat + 1)  # from +Y down
    phi = np.linspace(0.0, 2.0 * np.pi, n_lon + 1)  # the seam column repeated
    t, p = np.meshgrid(theta, phi, indexing="ij")
    pos = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], axis=-1)
    idx = np.arange((n_lat + 1) * (n_lon + 1)).reshape(n_lat + 1, n_lon + 1)
    a, b = idx[:-1, :-1], idx[1:, :-1]  # a above b
    c, d = idx[1:, 1:], idx[:-1, 1:]
    tris = np.concatenate(
        [np.stack([a, b, c], -1)[:-1], np.stack([a, c, d], -1)[1:]], axis=0
    ).reshape(-1, 3)  # the degenerate triangles at the poles left out
    return pos.reshape(-1, 3).astype(np.float32), tris


def add_sphere(doc: dict) -> dict:
    """``doc`` (a glTF document with ``materials``) with a unit sphere using material 0
    (module docstring); ``doc`` itself is not changed."""
    pos, tris = sphere()
    parts = [pos.tobytes(), pos.tobytes(), tris.astype(np.uint16).tobytes()]
    views, offset = [], 0
    for k, part in enumerate(parts):
        target = ELEMENT_ARRAY_BUFFER if k == 2 else ARRAY_BUFFER
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(part), "target": target})
        offset += len(part) + (-len(part) % 4)
    blob = b"".join(part + b"\0" * (-len(part) % 4) for part in parts)
    accessors = [
        {"bufferView": 0, "componentType": FLOAT, "count": len(pos), "type": "VEC3",
         "min": pos.min(axis=0).tolist(), "max": pos.max(axis=0).tolist()},
        {"bufferView": 1, "componentType": FLOAT, "count": len(pos), "type": "VEC3"},
        {"bufferView": 2, "componentType": UNSIGNED_SHORT, "count": tris.size, "type": "SCALAR"},
    ]  # fmt: skip
    primitive = {
        "attributes": {"POSITION": 0, "NORMAL": 1},
        "indices": 2,
        "material": 0,
        "mode": TRIANGLES,
    }
    uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")
    return doc | {
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "brdffit sphere"}],
        "meshes": [{"primitives": [primitive], "name": "unit sphere"}],
        "buffers": [{"byteLength": len(blob), "uri": uri}],
        "bufferViews": views,
        "accessors": accessors,
    }

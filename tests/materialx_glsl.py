"""MaterialX's own evaluation of ``open_pbr_surface``: the fragment shader MaterialX's GLSL
generator emits for a material, run per pixel on an OpenGL context (Mesa's llvmpipe on a
CPU machine), one light direction and one view direction per pixel.

The generated shader is used as emitted, with these edits (:func:`_patch`), each needed to
feed it directions instead of a scene, none touching a closure:

* the vertex data block becomes a global set in ``main`` (normal +z, tangent +x);
* the view vector and the light's direction come from two float textures, one texel per
  pixel; there is one light, of intensity 1 (``sampleLightSource`` bypassed);
* the output is the summed direct-light *response* of the material (no environment, no
  emission), so a pixel holds ``f(wi, wo) cos(theta_i)`` in float32;
* ``mx_acos`` (``#define mx_acos acos``) becomes ``atan(sqrt(1 - x^2), x)``: llvmpipe's
  ``acos`` is off by up to 1.6e-4 (measured), a driver's precision, not MaterialX's formula.

Needs ``moderngl`` and an EGL driver (Mesa). :func:`context` skips the calling test where
none can be made, or fails when ``BRDFFIT_REQUIRE_VALIDATORS=1`` (``.ci/run``).
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Mapping

import numpy as np
import pytest

VERTEX = "#version 400\nin vec2 in_pos;\nvoid main() { gl_Position = vec4(in_pos, 0.0, 1.0); }\n"


@functools.cache
def _context():
    import moderngl

    return moderngl.create_standalone_context(backend="egl", require=400)


def context():
    """The standalone OpenGL context, made once; skip (or fail, in CI) without one."""
    try:
        return _context()
    except Exception as err:  # moderngl missing, no EGL, no driver
        why = f"no OpenGL context for MaterialX's GLSL: {type(err).__name__}: {err}"
        if os.environ.get("BRDFFIT_REQUIRE_VALIDATORS") == "1":
            pytest.fail(why)
        pytest.skip(why)


def fragment_source(inputs: Mapping[str, object]) -> str:
    """The pixel shader MaterialX's GLSL generator emits for one ``open_pbr_surface``."""
    import MaterialX as mx
    from MaterialX import PyMaterialXGenGlsl as mx_glsl
    from MaterialX import PyMaterialXGenShader as mx_gen

    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    doc = mx.createDocument()
    doc.importLibrary(lib)
    shader = doc.addNode("open_pbr_surface", "SR_test", "surfaceshader")
    nodedef = lib.getNodeDef("ND_open_pbr_surface_surfaceshader")
    for name, value in inputs.items():
        kind = nodedef.getActiveInput(name).getType()
        port = shader.addInput(name, kind)
        if kind == "boolean":
            port.setValueString("true" if value else "false")
        else:
            flat = np.atleast_1d(np.asarray(value, float))
            flat = np.broadcast_to(flat, (3,)) if kind == "color3" else flat
            port.setValueString(", ".join(repr(float(x)) for x in flat))
    material = doc.addMaterialNode("M_test", shader)
    generator = mx_glsl.GlslShaderGenerator.create()
    ctx = mx_gen.GenContext(generator)
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    return _patch(generator.generate("test", material, ctx).getSourceCode(mx_gen.PIXEL_STAGE))


def _replace_once(src: str, old: str, new: str) -> str:
    assert src.count(old) == 1, f"generated GLSL changed: {old!r} found {src.count(old)} times"
    return src.replace(old, new)


def _patch(src: str) -> str:
    src, n = re.subn(
        r"in VertexData\s*\{[^}]*\}\s*vd;",
        "struct VertexData_ { vec3 normalWorld; vec3 tangentWorld; vec3 positionWorld; };\n"
        "VertexData_ vd;\nuniform sampler2D u_Ltex;\nuniform sampler2D u_Vtex;\n"
        "vec3 g_L; vec3 g_V; vec3 g_resp = vec3(0.0);",
        src,
    )
    assert n == 1, "generated GLSL changed: no VertexData block"
    src = _replace_once(
        src,
        "#define mx_acos acos",
        "float mx_acos(float x) { return atan(sqrt(max(1.0 - x * x, 0.0)), x); }",
    )
    src = _replace_once(
        src, "vec3 V = normalize(u_viewPosition - vd.positionWorld);", "vec3 V = g_V;"
    )
    src = _replace_once(src, "int numLights = numActiveLightSources();", "int numLights = 1;")
    src = _replace_once(
        src,
        "sampleLightSource(u_lightData[activeLightIndex], vd.positionWorld, lightShader);",
        "lightShader.direction = g_L; lightShader.intensity = vec3(1.0);",
    )
    # the last closure of the graph (the fuzz layer) is what reaches the surface
    add = "shader_constructor_out.color += lightShader.intensity * fuzz_layer_out.response;"
    src = _replace_once(
        src, add, add + " g_resp += lightShader.intensity * fuzz_layer_out.response;"
    )
    head, tail = src.rsplit("void main()\n{", 1)
    tail = _replace_once(tail, "out1 = vec4(M_test_out.color, 1.0);", "out1 = vec4(g_resp, 1.0);")
    setup = (
        "\n    ivec2 px = ivec2(gl_FragCoord.xy);\n"
        "    g_L = texelFetch(u_Ltex, px, 0).xyz; g_V = texelFetch(u_Vtex, px, 0).xyz;\n"
        "    vd.normalWorld = vec3(0.0, 0.0, 1.0); vd.tangentWorld = vec3(1.0, 0.0, 0.0);\n"
        "    vd.positionWorld = vec3(gl_FragCoord.xy, 0.0);\n"
    )
    return head + "void main()\n{" + setup + tail


def response(inputs: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(N, 3) ``f(wi, wo) cos(theta_i)`` of ``open_pbr_surface`` with ``inputs`` (names of its
    node definition), as MaterialX's GLSL computes it (float32, returned as float64);
    ``wi`` toward the light, ``wo`` toward the viewer, (N, 3) unit vectors, normal +z."""
    import moderngl

    gl = context()
    width = 64
    n = len(wi)
    height = -(-n // width)
    textures = []
    for k, d in enumerate((wi, wo)):
        texels = np.zeros((width * height, 4), "f4")
        texels[:, 2] = texels[:, 3] = 1.0
        texels[:n, :3] = d
        tex = gl.texture((width, height), 4, texels.tobytes(), dtype="f4")
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        tex.use(k)
        textures.append(tex)
    program = gl.program(vertex_shader=VERTEX, fragment_shader=fragment_source(inputs))
    program["u_Ltex"].value, program["u_Vtex"].value = 0, 1
    target = gl.texture((width, height), 4, dtype="f4")
    frame = gl.framebuffer(color_attachments=[target])
    frame.use()
    gl.viewport = (0, 0, width, height)
    quad = gl.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], "f4").tobytes())
    vao = gl.vertex_array(program, [(quad, "2f", "in_pos")])
    vao.render(moderngl.TRIANGLE_STRIP)
    out = np.frombuffer(frame.read(components=4, dtype="f4"), "f4").reshape(-1, 4)[:n, :3]
    for obj in (vao, quad, frame, target, program, *textures):
        obj.release()
    return out.astype(np.float64)

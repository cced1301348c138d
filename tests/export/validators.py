"""The formats' own validators, for the export tests.

* glTF: the Khronos glTF Validator (``gltf-validator`` on npm, the official validator
  compiled from Dart to JavaScript), run by Node.js on the written ``.gltf`` files
  (``gltf_validate.js``). The package is installed once into a per-user cache
  (:data:`NODE_CACHE`) with npm, pinned to :data:`GLTF_VALIDATOR`.
* MaterialX: the MaterialX library itself (PyPI ``materialx``): the document read, its
  standard libraries imported, ``Document.validate()``, every node resolved to a node
  definition (``validate`` passes a node whose category has none, such as a misspelt
  ``open_pbr_surfac``), and GLSL generated for every material, as MaterialX's viewer and
  renderers would.

Where Node.js, npm or the registry is missing the glTF check is skipped, unless
``BRDFFIT_REQUIRE_VALIDATORS=1`` (set by ``.ci/run``), where it fails: a validator that
silently did not run would be a test that cannot fail.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path

import pytest

GLTF_VALIDATOR = "gltf-validator@2.0.0-dev.3.10"
NODE_CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "brdffit-tests"
SCRIPT = Path(__file__).with_name("gltf_validate.js")


def _unavailable(why: str) -> None:
    if os.environ.get("BRDFFIT_REQUIRE_VALIDATORS") == "1":
        pytest.fail(f"glTF validator required (BRDFFIT_REQUIRE_VALIDATORS=1): {why}")
    pytest.skip(f"Khronos glTF validator unavailable: {why}")


def gltf_validator_modules() -> Path:
    """The ``node_modules`` folder holding the Khronos validator, installed on first use."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        _unavailable("node or npm not on PATH")
    prefix = NODE_CACHE / GLTF_VALIDATOR.replace("@", "-")
    modules = prefix / "node_modules"
    if not (modules / "gltf-validator" / "package.json").exists():
        prefix.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(
            ["npm", "install", "--prefix", str(prefix), "--no-audit", "--no-fund", GLTF_VALIDATOR],
            capture_output=True,
            text=True,
            timeout=300,
        )
        if done.returncode != 0:
            _unavailable(f"npm install {GLTF_VALIDATOR} failed: {done.stderr.strip()[-300:]}")
    return modules


def gltf_reports(paths: Sequence[Path], modules: Path) -> dict[str, dict]:
    """The validator's ``issues`` (numErrors, numWarnings, numInfos, messages) per file."""
    env = os.environ | {"NODE_PATH": str(modules)}
    done = subprocess.run(
        ["node", str(SCRIPT), *map(str, paths)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def mtlx_problems(text: str) -> list[str]:
    """What MaterialX finds wrong with a document: empty when it is valid and usable."""
    import MaterialX as mx
    from MaterialX import PyMaterialXGenGlsl as mx_glsl
    from MaterialX import PyMaterialXGenShader as mx_gen

    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    doc = mx.createDocument()
    mx.readFromXmlString(doc, text)
    doc.importLibrary(lib)
    ok, message = doc.validate()
    problems = [] if ok else [message.strip()]
    problems += [
        f"node {n.getName()!r} ({n.getCategory()}) has no node definition"
        for n in doc.getNodes()
        if n.getNodeDef() is None
    ]
    generator = mx_glsl.GlslShaderGenerator.create()
    context = mx_gen.GenContext(generator)
    context.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    materials = [n for n in doc.getNodes() if n.getType() == "material"]
    problems += [] if materials else ["no material node"]
    for m in materials:
        try:
            generator.generate(m.getName(), m, context)
        except Exception as err:  # MaterialX raises its own exception types
            problems.append(f"GLSL generation for {m.getName()!r} failed: {err}")
    return problems

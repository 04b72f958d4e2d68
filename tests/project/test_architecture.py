"""The package's shape (issue 26): the import contracts of pyproject.toml's [tool.importlinter]
(the layers, bottom to top, no file reader and no image or video library on the render path,
and no import cycle inside a package) hold, and they catch an import that breaks them; importing
a renderer loads no image or video library (issue 39 item 5); the top level stays small, and so
do modules and classes."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "splatgl"
PYPROJECT = ROOT / "pyproject.toml"

#: Modules directly in splatgl/ (not counting __init__ and __main__): new code goes in a package.
MAX_TOP_LEVEL_MODULES = 12
MAX_MODULE_LINES = 400
MAX_CLASS_LINES = 250


def test_import_contracts_hold():
    """``lint-imports`` passes; when it does not, the message names each offending import
    (``splatgl.order is not allowed to import splatgl.lod: splatgl.order.sort ->
    splatgl.lod.build (l.63)``) or cycle."""
    pytest.importorskip("importlinter", reason="import-linter is not installed (pip install '.[test]')")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    # lint-imports reads the contracts from pyproject.toml in the working directory
    run = subprocess.run([sys.executable, "-c", "from importlinter.cli import lint_imports_command; "
                          "lint_imports_command()", "--no-cache"],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    out = run.stdout + run.stderr
    broken = out[out.find("Broken contracts"):] if "Broken contracts" in out else out
    assert run.returncode == 0, f"import contracts broken:\n{broken}"
    assert " kept, 0 broken." in out, out


@pytest.fixture(scope="module")
def contracts():
    """``(graph, {contract id: (contract class, options)}, session options)`` from pyproject.toml,
    the graph built as ``lint-imports`` builds it."""
    pytest.importorskip("importlinter", reason="import-linter is not installed (pip install '.[test]')")
    import grimp
    from importlinter.api import read_configuration
    from importlinter.contracts.acyclic_siblings import AcyclicSiblingsContract
    from importlinter.contracts.forbidden import ForbiddenContract
    from importlinter.contracts.layers import LayersContract

    options = read_configuration(str(PYPROJECT))
    session = options["session_options"]
    assert session["root_packages"] == ["splatgl"]
    graph = grimp.build_graph("splatgl", exclude_type_checking_imports=True, cache_dir=None,
                              include_external_packages=session.get("include_external_packages", False))
    kinds = {"layers": LayersContract, "forbidden": ForbiddenContract,
             "acyclic_siblings": AcyclicSiblingsContract}
    found = {c["id"]: (kinds[c["type"]], c) for c in options["contracts_options"]}
    assert set(found) == {"layers", "render-path-reads-no-files", "render-path-loads-no-image-library",
                          "acyclic"}
    return graph, found, session


def _check(contracts, contract_id: str, *extra: tuple[str, str]):
    """The contract's check on the package's graph, with the ``(importer, imported)`` imports
    of ``extra`` added (as if modules had them)."""
    import copy

    graph, found, session = contracts
    graph = copy.deepcopy(graph)
    for importer, imported in extra:
        graph.add_import(importer=importer, imported=imported, line_number=1,
                         line_contents=f"import {imported}")
    cls, options = found[contract_id]
    return cls(name=options["name"], session_options=session, contract_options=options).check(
        graph, verbose=False)


@pytest.mark.parametrize("contract_id", ["layers", "render-path-reads-no-files",
                                         "render-path-loads-no-image-library", "acyclic"])
def test_contracts_kept_on_the_package(contracts, contract_id):
    assert _check(contracts, contract_id).kept


@pytest.mark.parametrize("importer, imported", [
    ("splatgl.order.sort", "splatgl.lod.build"),  # up a layer (the old morton_order import)
    ("splatgl.tasks.task", "splatgl.commands.bench"),  # up several
    ("splatgl.scene.splats", "splatgl.api"),  # from the bottom to the API
    ("splatgl.gl.buffers", "splatgl.reference.render"),  # between independent siblings
    ("splatgl.measure.bench.runner", "splatgl.viewer.app"),  # between independent siblings
    ("splatgl.output.under", "splatgl.imagefiles.under_exr"),  # data up to its file reader
    ("splatgl.writing.atomic", "splatgl.output.layers"),  # between independent siblings
])
def test_layers_contract_refuses_an_import_against_the_layers(contracts, importer, imported):
    """An import up the layers, or across packages that share a layer as independent siblings,
    breaks the contract, and the check names it."""
    check = _check(contracts, "layers", (importer, imported))
    assert not check.kept
    assert importer in repr(check.metadata) and imported in repr(check.metadata)


@pytest.mark.parametrize("imports", [
    [("splatgl.gl.storage", "splatgl.formats.quantise")],  # the old smallest_three import
    [("splatgl.order.cull", "splatgl.paths.keyframes")],
    # through a module the render path may import (writing.outputs), made to use a format
    [("splatgl.renderers.quad", "splatgl.writing.outputs"), ("splatgl.writing.outputs", "splatgl.formats.ply")],
], ids=["gl-formats", "order-paths", "through-output"])
def test_render_path_contract_refuses_file_imports(contracts, imports):
    """The render path imports no file reader or writer, directly or through another module."""
    check = _check(contracts, "render-path-reads-no-files", *imports)
    assert not check.kept
    assert imports[0][0] in repr(check.metadata)


@pytest.mark.parametrize("imports", [
    [("splatgl.output.under", "OpenImageIO")],  # the old --under reader, under the View
    [("splatgl.renderers.quad", "av")],
    [("splatgl.cameras.view", "PIL")],
    # through a module of the image files (which may load them)
    [("splatgl.renderers.mesh", "splatgl.imagefiles.images")],
], ids=["output-oiio", "renderer-av", "cameras-pillow", "through-imagefiles"])
def test_render_path_contract_refuses_image_libraries(contracts, imports):
    """The render path imports no image or video library (OpenImageIO, PyAV, Pillow), directly
    or through another module: they are splatgl.imagefiles' business."""
    check = _check(contracts, "render-path-loads-no-image-library", *imports)
    assert not check.kept
    assert imports[0][0] in repr(check.metadata)


#: Every module of the render path, and the API's, imported and used in a fresh interpreter.
_RENDER_PATH_PROBE = """
import importlib, pkgutil, sys
import splatgl.renderers, splatgl.reference, splatgl.cameras, splatgl.order
for package in (splatgl.renderers, splatgl.reference, splatgl.cameras, splatgl.order):
    for info in pkgutil.iter_modules(package.__path__, package.__name__ + "."):
        try:
            importlib.import_module(info.name)
        except ModuleNotFoundError as e:  # an optional dependency (numba kernels)
            if e.name.startswith("splatgl"):
                raise
import numpy as np
import splatgl
from splatgl.api import render_reference_layers
from splatgl.scene.splats import Scene
from splatgl.output.layers import Layer, with_layers
rng = np.random.default_rng(0)
scene = Scene(rng.normal(0, 0.5, (20, 3)), rng.normal(size=(20, 4)), rng.normal(-3, 0.3, (20, 3)),
              rng.normal(1, 1, 20), rng.normal(0, 0.3, (20, 1, 3)))
camera = splatgl.default_camera(scene, 16, 12)
render_reference_layers(scene, camera, splatgl.default_settings(scene), layers=with_layers(Layer.DEPTH))
try:
    splatgl.render(scene, camera)
except splatgl.ContextError:
    pass  # no OpenGL here: the imports were still made
print(sorted(m for m in ("OpenImageIO", "av", "PIL") if m in sys.modules))
"""


def test_rendering_loads_no_image_library():
    """Importing every renderer, reference and camera module and rendering through the API
    (the reference and, where OpenGL runs, the quad renderer) loads neither OpenImageIO, PyAV
    nor Pillow: before, the View imported the ``--under`` reader and with it OpenImageIO."""
    run = subprocess.run([sys.executable, "-c", _RENDER_PATH_PROBE], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().splitlines()[-1] == "[]"


@pytest.mark.parametrize("importer, imported", [
    ("splatgl.tasks.task", "splatgl.tasks.executor"),  # the old executor <-> local <-> ray cycle
    ("splatgl.order.cull", "splatgl.order.stage"),
])
def test_acyclic_contract_refuses_a_cycle_inside_a_package(contracts, importer, imported):
    check = _check(contracts, "acyclic", (importer, imported))
    assert not check.kept


def test_every_package_and_top_level_module_is_on_a_layer(contracts):
    """The layers contract is exhaustive: a new package or top-level module breaks it until it
    is given a layer."""
    graph, found, session = contracts
    import copy

    graph = copy.deepcopy(graph)
    graph.add_module("splatgl.unplaced")
    cls, options = found["layers"]
    check = cls(name=options["name"], session_options=session, contract_options=options).check(
        graph, verbose=False)
    assert not check.kept and "splatgl.unplaced" in repr(check.metadata)


def test_top_level_holds_few_modules():
    modules = sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem not in ("__init__", "__main__"))
    assert len(modules) <= MAX_TOP_LEVEL_MODULES, (
        f"{len(modules)} modules at the top of splatgl/ (at most {MAX_TOP_LEVEL_MODULES}): {modules}; "
        "put new code in the package it belongs to")


def _sources():
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path.relative_to(ROOT).as_posix(), path.read_text(encoding="utf-8")


def test_no_module_over_400_lines():
    over = {name: n for name, text in _sources() if (n := len(text.splitlines())) > MAX_MODULE_LINES}
    assert not over, f"modules over {MAX_MODULE_LINES} lines: {over}"


def test_no_class_over_250_lines():
    over = {}
    for name, text in _sources():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef) and node.end_lineno - node.lineno + 1 > MAX_CLASS_LINES:
                over[f"{name}:{node.name}"] = node.end_lineno - node.lineno + 1
    assert not over, f"classes over {MAX_CLASS_LINES} lines: {over}"

"""The binding table (splatgl/gl/bindings.py): binding points, texture units and work-group sizes
are written once, as names, and every shader and every Python bind uses the names.

The rule checked for binding points (the table's module doc): within a family (the programs one
renderer runs in a frame after binding its buffers once) every point is distinct; families may
share points.  A shader's storage blocks all come from one storage family and its samplers from
one texture family, so a program never mixes, say, the tile renderer's points with the quad
path's.
"""

from __future__ import annotations

import re
from pathlib import Path

from splatgl import constants
from splatgl.gl import bindings
from splatgl.gl.shaders import preprocess, shader_dir

REPO = Path(__file__).resolve().parents[2]
VIEWER_SHADERS = REPO / "splatgl" / "viewer" / "shaders"
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
_BINDING = re.compile(r"\bbinding\s*=\s*(\w+)")
_LOCAL_SIZE = re.compile(r"\blocal_size_[xyz]\s*=\s*(\w+)")
_BLOCK = re.compile(r"\bbinding\s*=\s*(\w+)\s*\)[^;{]*?\bbuffer\s+(\w+)")


def _shader_files() -> list[Path]:
    root = shader_dir()
    files = sorted(p for p in root.rglob("*") if p.suffix in (".glsl", ".comp", ".vert", ".frag"))
    return files + sorted(VIEWER_SHADERS.glob("*.*"))


def _code(path: Path) -> str:
    """The file without its comments."""
    return re.sub(r"//[^\n]*", "", path.read_text())


def _closure(path: Path) -> list[Path]:
    """``path`` and every file it may include (all camera pieces for ``{CAMERA_MODEL}``)."""
    root = shader_dir() if shader_dir() in path.parents else path.parent
    seen: list[Path] = []
    todo = [path]
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        seen.append(p)
        for rel in _INCLUDE.findall(p.read_text()):
            todo += sorted(root.glob(re.sub(r"\{\w+\}", "*", rel)))
    return seen


def test_shaders_write_no_binding_or_work_group_number():
    """A number after ``binding =`` or ``local_size_x =`` is a second copy of the table."""
    literal = re.compile(r"\b(binding|local_size_[xyz])\s*=\s*\d")
    found = [f"{p.relative_to(REPO)}:{i}: {line.strip()}"
             for p in _shader_files()
             for i, line in enumerate(p.read_text().splitlines(), start=1)
             if literal.search(line.split("//")[0])]
    assert not found, "numbers typed in shaders (use a name of splatgl/gl/bindings.py):\n" + "\n".join(found)


def test_python_binds_by_name():
    """No storage binding or texture unit is typed as a number in the package either."""
    literal = re.compile(r"(bind_to_storage_buffer|\.use|GrowableBuffer\(\s*\w+,)\(?\s*\d")
    found = [f"{p.relative_to(REPO)}:{i}: {line.strip()}"
             for p in sorted((REPO / "splatgl").rglob("*.py"))
             for i, line in enumerate(p.read_text().splitlines(), start=1)
             if literal.search(line.split("#")[0])]
    assert not found, "\n".join(found)


def test_shader_names_come_from_the_table():
    """Every name is the table's, and a block declared in several files (Prepared, StopTiles,
    SplatSH, ...) sits at one name everywhere."""
    table = bindings.table()
    where: dict[str, tuple[str, str]] = {}
    for path in _shader_files():
        code = _code(path)
        for name in _BINDING.findall(code):
            assert name in table, f"{path.name}: binding = {name} is not in splatgl/gl/bindings.py"
        for name in _LOCAL_SIZE.findall(code):
            assert name in table or name == "TILE_SIZE", f"{path.name}: local_size = {name}"
        for name, block in _BLOCK.findall(code):
            first = where.setdefault(block, (name, path.name))
            assert first[0] == name, f"{block}: {name} in {path.name}, {first[0]} in {first[1]}"
    assert {"Prepared", "StopTiles", "SplatSH", "Order"} <= set(where)


def test_points_are_unique_within_each_family():
    table = bindings.table()
    for family, names in bindings.FAMILIES.items():
        assert set(names) <= set(table), f"{family}: {sorted(set(names) - set(table))}"
        values: dict[int, str] = {}
        for name in names:
            other = values.setdefault(table[name], name)
            assert other == name, f"{family}: {name} and {other} share point {table[name]}"
    in_a_family = {name for names in bindings.FAMILIES.values() for name in names}
    points = {name for name in table if "BINDING" in name or name.endswith("_UNIT")}
    assert points == in_a_family, f"in no family: {sorted(points - in_a_family)}"


def test_each_program_binds_within_one_family():
    """Storage blocks of a stage file and its includes lie in one storage family, samplers in one
    texture family."""
    storage = [set(n) for f, n in bindings.FAMILIES.items() if f.endswith("storage")]
    textures = [set(n) for f, n in bindings.FAMILIES.items() if f.endswith("textures")]
    stages = [p for p in _shader_files() if p.suffix != ".glsl"]
    assert len(stages) > 15
    for stage in stages:
        names = {n for p in _closure(stage) for n in _BINDING.findall(_code(p))}
        blocks = {n for n in names if "BINDING" in n}
        units = names - blocks
        assert not blocks or any(blocks <= f for f in storage), f"{stage.name}: {sorted(blocks)}"
        assert not units or any(units <= f for f in textures), f"{stage.name}: {sorted(units)}"


def test_every_program_receives_the_table_with_the_constants():
    text = preprocess("radix_upsweep.comp").text
    for name, value in bindings.glsl_defines().items():
        assert f"#define {name} {value}\n" in text
    assert f"#define TILE_SIZE {constants.TILE_SIZE}\n" in text
    assert "RADIX_GROUP" not in constants.glsl_defines()  # one place: the table


def test_compiled_blocks_sit_at_the_table_points(ctx):
    """What the compiler made of the names: each storage block's binding is the table's value
    for the name its declaration uses."""
    from splatgl.cameras.registry import MODELS
    from splatgl.gl.shaders import ProgramCache

    declared = {block: name for p in _shader_files() for name, block in _BLOCK.findall(_code(p))}
    table = bindings.table()
    base = {**MODELS["perspective"]().defines(), "SH_DEGREE": 1, "SH_REST_COEFFS": 3}
    cache = ProgramCache(ctx)
    programs = [cache.compute("quad_prepass.comp", {**base, "OPACITY_WEIGHT": 1}),
                cache.compute("occlusion_cull.comp", {**base, "PREPARED": 1}),
                cache.compute("coverage.comp", base),
                cache.compute("stop_tiles.comp"),
                cache.compute("radix_downsweep.comp"),
                cache.compute("tile_rasterize.comp", {**base, "TILE_LIST_CHUNK": 16, "TILE_EMIT_CHUNK": 16})]
    checked = 0
    try:
        for prog in programs:
            for member in prog:
                binding = getattr(prog[member], "binding", None)
                if type(prog[member]).__name__ == "StorageBlock":
                    assert binding == table[declared[member]], member
                    checked += 1
    finally:
        cache.release()
    assert checked >= 15


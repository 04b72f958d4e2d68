"""The shader include preprocessor: expansion, include-once, errors by file and line, cache."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from splatgl.errors import ShaderError
from splatgl.gl.shaders import ProgramCache, preprocess, shader_dir


def _write(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_includes_expand_once_with_constants_and_defines(tmp_path):
    root = _write(tmp_path, {
        "lib/a.glsl": "float a() { return ALPHA_MAX; }\n",
        "lib/b.glsl": '#include "lib/a.glsl"\nfloat b() { return a(); }\n',
        "main.comp": '#version 430\n#include "lib/a.glsl"\n#include "lib/b.glsl"\nvoid main() {}\n',
    })
    src = preprocess("main.comp", {"SH_DEGREE": "2"}, root=root)
    assert src.files == ("main.comp", "lib/a.glsl", "lib/b.glsl")
    assert src.text.count("float a()") == 1
    assert src.text.startswith("#version 430 core\n")
    assert "#define ALPHA_MAX 0.99" in src.text and "#define SH_DEGREE 2" in src.text


def test_missing_include_and_cycle_name_file_and_line(tmp_path):
    root = _write(tmp_path, {
        "x.comp": 'void f();\n#include "lib/none.glsl"\n',
        "lib/p.glsl": '#include "lib/q.glsl"\n', "lib/q.glsl": '\n#include "lib/p.glsl"\n',
        "y.comp": '#include "lib/p.glsl"\n',
    })
    with pytest.raises(ShaderError, match=r"x\.comp:2: shader file 'lib/none.glsl' not found"):
        preprocess("x.comp", root=root)
    with pytest.raises(ShaderError, match=r"lib/q\.glsl:2: include cycle"):
        preprocess("y.comp", root=root)


def test_compile_error_reports_the_included_file_and_line(tmp_path, gl_renderer):
    root = _write(tmp_path, {
        "lib/bad.glsl": "float ok() { return 1.0; }\nfloat bad() { return undefined_thing; }\n",
        "c.comp": '#version 430\n#include "lib/bad.glsl"\nlayout(local_size_x = 1) in;\n'
                  "void main() { float x = bad(); }\n",
    })
    src = preprocess("c.comp", root=root)
    try:
        gl_renderer.ctx.compute_shader(src.text)
    except Exception as exc:  # moderngl.Error
        text = src.describe(str(exc))
    else:
        pytest.fail("the broken shader compiled")
    assert re.search(r"lib/bad\.glsl:2\b", text) and "undefined_thing" in text  # Mesa "f:2(3)", NVIDIA "f:2 :"


def test_every_quad_variant_compiles_and_is_cached(gl_renderer):
    """All specialisations of the quad program (the tile shaders compile in test_tile.py)."""
    assert (shader_dir() / "quad.vert").is_file()
    from splatgl.cameras.registry import MODELS

    cache = ProgramCache(gl_renderer.ctx)
    pinhole = MODELS["perspective"]().defines()
    variants = [{**pinhole, "EXTENT_SQUARE": 1}, {**pinhole, "ANTIALIAS": 1},
                *(model().defines() for model in MODELS.values())]
    for degree in range(4):
        for extra in variants:
            defines = {"SH_DEGREE": degree, "SH_REST_COEFFS": 15, **extra}
            prog = cache.program("quad.vert", "quad.frag", defines)
            assert cache.program("quad.vert", "quad.frag", dict(defines)) is prog
    assert len(cache._programs) == 4 * len(variants)
    cache.release()


def test_include_paths_take_defines(tmp_path):
    """``#include "cameras/{CAMERA_MODEL}.glsl"`` includes the piece the define names; without
    the define the error names the file and line."""
    root = _write(tmp_path, {"main.comp": '// top\n#include "pieces/{WHICH}.glsl"\n',
                             "pieces/a.glsl": "float a_piece;\n", "pieces/b.glsl": "float b_piece;\n"})
    assert "a_piece" in preprocess("main.comp", {"WHICH": "a"}, root=root).text
    assert "b_piece" in preprocess("main.comp", {"WHICH": "b"}, root=root).text
    with pytest.raises(ShaderError, match="main.comp:2: include path 'pieces/{WHICH}.glsl' needs the define WHICH"):
        preprocess("main.comp", {}, root=root)


def test_errors_in_both_stages_map_to_their_own_files(tmp_path, gl_renderer):
    root = _write(tmp_path, {
        "v.vert": "#version 430\nvoid main() { gl_Position = vec4(undefined_v); }\n",
        "f.frag": "#version 430\nout vec4 c;\n\nvoid main() { c = vec4(undefined_f); }\n",
    })
    from splatgl.gl.shaders import _describe_log

    sources = {"vertex": preprocess("v.vert", root=root), "fragment": preprocess("f.frag", root=root)}
    try:
        gl_renderer.ctx.program(vertex_shader=sources["vertex"].text, fragment_shader=sources["fragment"].text)
    except Exception as exc:
        text = _describe_log(str(exc), sources)
    else:
        pytest.fail("the broken program compiled")
    assert re.search(r"v\.vert:2\b", text) and "undefined_v" in text
    if "undefined_f" in text:  # Mesa stops after the first failing stage
        assert "f.frag:4(" in text


@pytest.mark.parametrize("name", ["quad.frag", "surfel.frag"])
def test_splat_fragment_stages_never_discard(name):
    """llvmpipe ignores layout(early_fragment_tests) in a shader that can discard, so early
    termination's rejected fragments would be shaded all the same (docs/design.md, traps): the
    splat fragment stages write (0, 0, 0, 0) for a skipped fragment instead.  Every variant's
    expanded source (includes and all) is checked, comments aside."""
    import re

    from splatgl.cameras.registry import MODELS

    pinhole, equirect = MODELS["perspective"]().defines(), MODELS["equirectangular"]().defines()
    for defines in (pinhole, {**pinhole, "EARLY_STOP": "1"}, {**equirect, "DEPTH_OUTPUT": "1"}):
        code = re.sub(r"//[^\n]*", "", preprocess(name, defines).text)
        assert not re.search(r"\bdiscard\b", code), f"{name} {defines}"

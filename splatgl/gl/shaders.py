"""Shader files: locating them, an ``#include`` preprocessor, and a program cache.

Shaders live in the top-level ``shaders/`` folder (shipped in the wheel as ``splatgl/shaders``).
A stage file may ``#include "lib/name.glsl"``; each file is included once per stage.  A ``{NAME}``
in an include path is replaced by the value of the define ``NAME`` (``#include
"cameras/{CAMERA_MODEL}.glsl"`` includes the camera model's piece).  The
preprocessor emits ``#line`` directives that encode the file in the line number, so compiler messages are
mapped back to ``file:line``.  Programs are specialised by generated ``#define`` lines (the reference
constants of :mod:`splatgl.constants`, the binding points and work-group sizes of
:mod:`splatgl.gl.bindings`, plus per-variant switches) and cached by (names, defines).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import moderngl

from ..constants import glsl_defines
from .bindings import glsl_defines as binding_defines
from ..errors import ShaderError

GLSL_VERSION = "#version 430 core"
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_PLACEHOLDER = re.compile(r"\{(\w+)\}")
_MESA_MSG = re.compile(r"(\d+):(\d+)\((\d+)\)")
_NVIDIA_MSG = re.compile(r"(\d+)\((\d+)\)")
#: ``#line`` numbers are ``file_index * LINE_STRIDE + line`` (see :meth:`Source.describe`).
LINE_STRIDE = 100000


def shader_dir() -> Path:
    """The shader folder: inside the installed package, or the repository's ``shaders/``."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here / "shaders", here.parent / "shaders"):
        if (candidate / "lib").is_dir():
            return candidate
    raise ShaderError(f"shader folder not found next to {here} (broken installation?)")


@dataclass(frozen=True)
class Source:
    """Preprocessed GLSL and the file each ``#line`` source number stands for."""

    text: str
    files: tuple[str, ...]

    def describe(self, log: str) -> str:
        """Rewrite ``S:line(col)`` (Mesa) or ``S(line)`` (NVIDIA) references as ``file:line``.

        Line numbers carry the file: ``#line`` sets them to ``file_index * LINE_STRIDE + line``
        (Mesa attributes some errors to the wrong source-string number, never to a wrong line).
        """

        def name(encoded: int) -> str:
            idx, line = divmod(encoded, LINE_STRIDE)
            return f"{self.files[idx] if idx < len(self.files) else f'<{idx}>'}:{line}"

        out = _MESA_MSG.sub(lambda m: f"{name(int(m.group(2)))}({m.group(3)})", log)
        if out == log:
            out = _NVIDIA_MSG.sub(lambda m: name(int(m.group(2))), log)
        return out


def preprocess(name: str, defines: dict[str, str] | None = None, root: Path | None = None) -> Source:
    """Expand ``name`` (relative to the shader folder) into one GLSL string.

    Adds the version line, the reference constants, the binding table
    (:mod:`splatgl.gl.bindings`) and ``defines`` as ``#define`` lines.
    Raises :class:`ShaderError` naming ``file:line`` for a missing include or an include cycle.
    """
    root = root or shader_dir()
    files: list[str] = []
    included: set[str] = set()
    out: list[str] = [GLSL_VERSION]
    all_defines = {**glsl_defines(), **binding_defines(), **(defines or {})}
    out += [f"#define {k} {v}".rstrip() for k, v in sorted(all_defines.items())]

    def expand(rel: str, stack: tuple[str, ...], where: str) -> None:
        if rel in stack:
            raise ShaderError(f"{where}: include cycle {' -> '.join(stack + (rel,))}")
        if rel in included:
            return
        path = root / rel
        if not path.is_file():
            raise ShaderError(f"{where}: shader file '{rel}' not found in {root}")
        included.add(rel)
        number = len(files)
        files.append(rel)
        out.append(f"#line {number * LINE_STRIDE + 1}")
        for lineno, line in enumerate(path.read_text().splitlines(), start=1):
            m = _INCLUDE.match(line)
            if m:
                expand(_fill(m.group(1), all_defines, f"{rel}:{lineno}"), stack + (rel,), f"{rel}:{lineno}")
                out.append(f"#line {number * LINE_STRIDE + lineno + 1}")
            elif line.lstrip().startswith("#version"):
                out.append("")  # the version line is emitted once, above
            else:
                out.append(line)

    expand(name, (), "(top)")
    return Source("\n".join(out) + "\n", tuple(files))


def _fill(path: str, defines: dict, where: str) -> str:
    """``path`` with each ``{NAME}`` replaced by the define's value (a ShaderError at ``where``
    when the define is missing)."""
    def value(m: re.Match) -> str:
        if m.group(1) not in defines:
            raise ShaderError(f"{where}: include path '{path}' needs the define {m.group(1)}")
        return str(defines[m.group(1)])
    return _PLACEHOLDER.sub(value, path)


def _describe_log(log: str, sources: dict[str, Source]) -> str:
    """Map each stage's section of a moderngl compile log (headed ``vertex_shader``,
    ``fragment_shader``, ``compute_shader``) through that stage's :meth:`Source.describe`."""
    headers = [(log.find(f"{stage}_shader\n"), stage) for stage in sources]
    headers = sorted((pos, stage) for pos, stage in headers if pos >= 0)
    if not headers:
        return next(iter(sources.values())).describe(log) if len(sources) == 1 else log
    out = [log[:headers[0][0]]]
    for i, (pos, stage) in enumerate(headers):
        end = headers[i + 1][0] if i + 1 < len(headers) else len(log)
        out.append(sources[stage].describe(log[pos:end]))
    return "".join(out)


def _define_key(defines: dict[str, object] | None) -> tuple[tuple[str, str], ...]:
    return tuple(sorted((k, str(v)) for k, v in (defines or {}).items()))


class ProgramCache:
    """Compiles programs on first use and keeps them, keyed by (stage files, defines)."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._programs: dict[tuple, moderngl.Program | moderngl.ComputeShader] = {}

    def _compile(self, kind: str, sources: dict[str, Source]):
        try:
            if kind == "compute":
                return self.ctx.compute_shader(sources["compute"].text)
            return self.ctx.program(
                vertex_shader=sources["vertex"].text, fragment_shader=sources["fragment"].text
            )
        except moderngl.Error as exc:
            log = _describe_log(str(exc), sources)
            raise ShaderError(f"shader compile failed ({', '.join(s.files[0] for s in sources.values())}):\n{log}") from None

    def program(self, vertex: str, fragment: str, defines: dict[str, object] | None = None) -> moderngl.Program:
        key = ("render", vertex, fragment, _define_key(defines))
        if key not in self._programs:
            d = dict(_define_key(defines))
            self._programs[key] = self._compile(
                "render", {"vertex": preprocess(vertex, d), "fragment": preprocess(fragment, d)}
            )
        return self._programs[key]

    def compute(self, name: str, defines: dict[str, object] | None = None) -> moderngl.ComputeShader:
        key = ("compute", name, _define_key(defines))
        if key not in self._programs:
            self._programs[key] = self._compile("compute", {"compute": preprocess(name, dict(_define_key(defines)))})
        return self._programs[key]

    def release(self) -> None:
        for prog in self._programs.values():
            prog.release()
        self._programs.clear()

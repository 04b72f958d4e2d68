"""Where every GL program's resources sit: storage-buffer binding points, texture units and
work-group sizes, in one table.

Python binds and dispatches with these names; GLSL receives the same names as generated
``#define`` lines (:func:`glsl_defines`, added by :func:`splatgl.gl.shaders.preprocess` to every
program like the constants of :mod:`splatgl.constants`), so a shader writes ``layout(std430,
binding = BINDING_ORDER)`` and ``layout(local_size_x = PREPASS_GROUP) in;`` and no number is
typed twice (tests/gl/test_bindings.py fails on a literal one).

The rule for binding points (checked by the test over :data:`FAMILIES`): a point is context
state, so a buffer stays there until another is bound at it.  A *family* is what one renderer
runs in a frame after binding its buffers once: within a family every point is distinct.
Different families may share points, because each binds all of its buffers before its own
passes: the quad path binds the scene in ``QuadRenderer.prepare``, after the device sort; the
tile renderer binds everything before each stage; the radix sort binds its five before each run.
"""

from __future__ import annotations

# --- The scene, uploaded once (gl/scene_buffers.py; shaders/lib/scene.glsl): every program
# that reads splats.  BINDING_A holds splat_a, or splat_packed with COMPACT_STORAGE.
BINDING_A = 0
BINDING_Q = 1
BINDING_S = 2
BINDING_DC = 3
BINDING_SH = 4

# --- The quad path (renderers/quad_gpu.py, batches.py; measure/bench/probes.py).
#: Sorted rows: quad_prepass.comp, lib/splat_rect.glsl (occlusion_cull.comp, coverage.comp).
BINDING_ORDER = 5
#: The pre-pass's quads: quad_prepass.comp writes, quad_light.vert, limit.vert and
#: lib/splat_rect.glsl (PREPARED) read.
BINDING_PREPARED = 6
#: The benchmark's fragment counters: quad.frag (COUNT_FRAGMENTS, COUNT_RASTERISED).
BINDING_FRAGMENT_COUNTS = 7
#: Early termination: stop_tiles.comp writes the stop words, occlusion_cull.comp reads them and
#: writes the survivors and draw commands; coverage.comp writes its partial sums.
BINDING_STOP_TILES = 8
BINDING_SURVIVORS = 9
BINDING_COMMANDS = 10
#: A level-of-detail cut's per-slot opacity weights: quad_prepass.comp (OPACITY_WEIGHT).
BINDING_OPACITY_WEIGHT = 11
BINDING_COVERAGE = 12
#: The normal layer's per-slot camera-space normals: quad_prepass.comp (NORMAL_OUTPUT) writes,
#: quad_light.vert reads.
BINDING_PREPARED_NORMAL = 13
#: The ordered pass's per-slot reference radius: quad_prepass.comp (ORDERED_RECT) writes,
#: quad_light.vert (ORDERED_PASS) reads.
BINDING_PREPARED_RADIUS = 14

# --- The tile renderer's per-view buffers (renderers/tile.py; shaders/lib/tile_common.glsl,
# tile_project.comp, tile_emit.comp, tile_rasterize.comp), after the scene's.
TILE_BINDING_MEAN_DEPTH = 5
TILE_BINDING_CONIC_O = 6
TILE_BINDING_COLOR = 7
TILE_BINDING_RECT = 8
TILE_BINDING_TOUCHED = 9
TILE_BINDING_OFFSETS = 10
TILE_BINDING_KEYS = 11
TILE_BINDING_VALUES = 12
TILE_BINDING_RANGES = 13
TILE_BINDING_OUT_RGBA = 14
TILE_BINDING_OUT_DEPTH = 15
TILE_BINDING_SURFEL = 16
#: The further layers (splatgl/output/layers.py): per-splat camera-space normals (NORMAL_OUTPUT,
#: tile_project.comp writes), per-pixel accumulated normals, the ordered layers' state
#: (ORDERED_OUTPUT: (median z, top weight) and (count, top index + 1)) and the geometry depth
#: splats are tested against (UNDER).
TILE_BINDING_NORMAL = 17
TILE_BINDING_OUT_NORMAL = 18
TILE_BINDING_OUT_ORDERED_F = 19
TILE_BINDING_OUT_ORDERED_U = 20
TILE_BINDING_UNDER = 21
#: The per-pixel order's peak-depth coefficients (tile_project.comp writes, tile_rasterize.comp reads).
TILE_BINDING_PEAK = 22
#: The device order (``--sort gpu``, renderers/tile_device.py; DEVICE_SORT in lib/tile_common.glsl):
#: the order's state and indirect dispatch arguments, the scan's per-block sums, the sorted
#: splat indices the rasterizer reads, and the radix sorter's keys and values (its A buffers).
TILE_BINDING_STATE = 23
TILE_BINDING_SCAN_BLOCKS = 24
TILE_BINDING_ORDER = 25
TILE_BINDING_SORT_KEYS = 26
TILE_BINDING_SORT_VALUES = 27
#: The splats in depth order (DEVICE_PRESORT: the scan and emission walk them in it).
TILE_BINDING_SPLAT_ORDER = 28

# --- The device radix sort (gl/radix_sort.py; shaders/radix_*.comp, lib/radix.glsl).
RADIX_BINDING_KEYS_IN = 0
RADIX_BINDING_VALS_IN = 1
RADIX_BINDING_KEYS_OUT = 2
RADIX_BINDING_VALS_OUT = 3
RADIX_BINDING_HIST = 4
#: The plan, the key bits seen and the digit totals; also the indirect dispatch buffer.
RADIX_BINDING_STATE = 5

# --- Texture units.
#: Early termination samples the accumulation target here: stop_mark.frag, stop_tiles.comp.
ACCUM_UNIT = 0
#: The geometry depth the quad path's fragments are tested against (quad.frag, surfel.frag
#: with UNDER).
UNDER_UNIT = 1
#: The viewer's present program samples its image here (splatgl/viewer/shaders/present.frag).
PRESENT_UNIT = 0
#: The draft upscaler samples the small frame here (shaders/upscale.frag).
UPSCALE_UNIT = 0

# --- Work-group sizes (local_size_x) and the dispatch shapes built on them.  tile_rasterize.comp
# runs TILE_SIZE x TILE_SIZE groups (splatgl.constants.TILE_SIZE, one invocation per pixel).
#: quad_prepass.comp.
PREPASS_GROUP = 128
#: coverage.comp.
COVERAGE_GROUP = 64
#: stop_tiles.comp: tiles per work group (one invocation per tile).
STOP_TILES_GROUP = 64
#: occlusion_cull.comp: a group owns OCCLUSION_GROUP * OCCLUSION_PER_INVOCATION sorted slots
#: (one draw command, renderers/early_stop.py SEGMENT).
OCCLUSION_GROUP = 256
OCCLUSION_PER_INVOCATION = 4
#: tile_project.comp, tile_emit.comp (one invocation per splat, lib/tile_common.glsl).
SPLAT_GROUP = 256
#: tile_scan.comp: threads per block of the scan of tiles touched (TILE_SCAN_ITEMS each).
TILE_SCAN_GROUP = 256
#: radix_bits.comp, radix_upsweep.comp, radix_downsweep.comp, radix_copy.comp: threads per
#: group; a group owns a tile of RADIX_GROUP * RADIX_ITEMS keys (splatgl.constants.RADIX_ITEMS).
#: radix_downsweep.comp keeps a 256-digit histogram per warp in shared memory: 16 KB with
#: 8-lane subgroups (llvmpipe).
RADIX_GROUP = 128
#: radix_scan.comp: threads per digit's scan over the tiles.
RADIX_SCAN_GROUP = 64
#: radix_downsweep.comp without subgroup operations: threads that exchange digits as one warp.
RADIX_PORTABLE_WARP = 16
#: radix_block_*.comp (software devices, gl/radix_block.py): lanes of a work group, each owning
#: a contiguous block of keys (llvmpipe's 8 SIMD lanes at 256 bits), and the threads of the
#: block scan's one work group.
RADIX_BLOCK_LANES = 8
RADIX_BLOCK_SCAN_GROUP = 64

#: order_cull.comp, order_scan.comp, order_compact.comp (the device-resident order,
#: splatgl/renderers/quad_device.py): the cull data (two vec4 per splat), each splat's staged
#: key, each work group's kept count (then its first slot), the indirect draw command (whose
#: instance count the scan writes; the pre-pass's dispatch size after it), and the sort's keys
#: and values (the radix sorter's A buffers) the compaction fills.
ORDER_BINDING_CULL = 15
ORDER_BINDING_STAGED = 16
ORDER_BINDING_BLOCKS = 17
ORDER_BINDING_COMMAND = 18
ORDER_BINDING_KEYS = 19
ORDER_BINDING_VALUES = 20
#: stop_plan.comp: one invocation plans early termination with the device order.
STOP_PLAN_GROUP = 1
#: order_cull.comp, order_compact.comp: splats per work group (one invocation each).
ORDER_GROUP = 128
#: order_scan.comp: threads of its one work group (each scans a run of the groups' counts).
ORDER_SCAN_GROUP = 256
#: quad_prepass.comp with DEVICE_COUNT: the device order's draw command, whose instance count
#: (the kept splats) bounds the slots it prepares.
BINDING_DEVICE_COUNT = 15
#: Early termination with the device order (renderers/early_stop_device.py): stop_plan.comp's
#: plan (batch bounds, the passes' indirect commands), read by occlusion_cull.comp
#: (DEVICE_BATCHES).
BINDING_STOP_PLAN = 16

#: Programs that bind together (see the module doc): in each, every binding point is distinct.
_SCENE = ("BINDING_A", "BINDING_Q", "BINDING_S", "BINDING_DC", "BINDING_SH")
FAMILIES: dict[str, tuple[str, ...]] = {
    "quad path storage": _SCENE + (
        "BINDING_ORDER", "BINDING_PREPARED", "BINDING_FRAGMENT_COUNTS", "BINDING_STOP_TILES",
        "BINDING_SURVIVORS", "BINDING_COMMANDS", "BINDING_OPACITY_WEIGHT", "BINDING_COVERAGE",
        "BINDING_PREPARED_NORMAL", "BINDING_PREPARED_RADIUS", "BINDING_DEVICE_COUNT",
        "BINDING_STOP_PLAN"),
    "tile renderer storage": _SCENE + tuple(
        name for name in globals() if name.startswith("TILE_BINDING_")),
    "device order storage": _SCENE + tuple(
        name for name in globals() if name.startswith("ORDER_BINDING_")),
    "radix sort storage": tuple(name for name in globals() if name.startswith("RADIX_BINDING_")),
    "quad path textures": ("ACCUM_UNIT", "UNDER_UNIT"),
    "viewer textures": ("PRESENT_UNIT",),
    "upscale textures": ("UPSCALE_UNIT",),
}
#: The tile renderer's buffers by name (``TILE_BINDING_<name>``): tile.py allocates one each.
TILE_BINDINGS: dict[str, int] = {name[len("TILE_BINDING_"):]: value
                                 for name, value in globals().items()
                                 if name.startswith("TILE_BINDING_")}


def table() -> dict[str, int]:
    """Every entry of the table: name -> value (the integer constants above)."""
    return {name: value for name, value in globals().items()
            if name.isupper() and not name.startswith("_") and type(value) is int}


def glsl_defines() -> dict[str, str]:
    """The table as GLSL ``#define`` values (name -> literal)."""
    return {name: str(value) for name, value in table().items()}

"""The guards the stress cases led to, with what each case measured before the guard existed.

Every entry was filled in from a run of ``splatgl stress`` on the code before that guard (the
2-core llvmpipe development machine); ``where`` names the code that carries the guard and its
reason as a comment.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Fix:
    """One guard: a title, where it lives, and the failures measured before it (one line each)."""

    title: str
    where: str
    before: tuple[str, ...]


FIXES: tuple[Fix, ...] = (
    Fix("means relative to a scene anchor, the anchor folded into the camera in float64",
        "Scene.anchor / relative_means (scene.py); anchored_camera, anchored (project.py); used "
        "by gl/scene_buffers.py, quad.py (cull, sort, uniforms), tile.py, reference/stages.py",
        ("far_1e5: tile 0.0104, reference32 0.0104 (quad 0.0104, inside its bound)",
         "far_1e6: quad 0.126, tile 0.126, reference32 0.126",
         "far_1e7: quad 0.790, tile 0.790, reference32 0.790 (the 5 x 5 grid shredded)",
         "ortho_huge_zoom: tile 0.0189, reference32 0.0189 (scene at 1 + 4e-5, 1e6 px/unit)")),
    Fix("near plane rounded down to float32, so z > near agrees with float64",
        "near_threshold (project.py); quad.set_camera_uniforms (u_near), reference/stages.py",
        ("near_plane: quad 0.413, tile 0.413, reference32 0.413 (a splat whose stored z is "
         "float32(0.1) = 0.10000000149 culled by float32 paths, kept by float64)",)),
    Fix("degenerate quaternions (zero, norm < 1e-12, non-finite) skipped: opacity 0, identity "
        "rotation, never NaN", "Scene.opacities / rotations (scene.py)",
        ("zero_quats: quad 0.752, tile 0.752, reference32 0.752 (a 1e-30 quaternion drawn as the "
         "identity; exact zeros became NaN rotations, dropped only by non-finite checks, with "
         "NumPy 'invalid value in divide' warnings)",)),
    Fix("det of the 2D covariance from the squared minors of M = J W R S where a c - b^2 "
        "cancels (below 1e-2 a c)",
        "covariance_2d_det (project.py, shaders/lib/project.glsl); splat_setup.glsl, "
        "tile_project.comp; DET_CANCEL_RATIO (constants.py)",
        ("det_nonpositive: quad 0.353, tile 0.253, reference32 0.252 (det <= 0 after "
         "cancellation: the needles culled)",)),
    Fix("quad minor axis lam2 = det / lam1 (clamped to [0, lam1]) instead of mid - root",
        "ellipse_axes (project.py, shaders/lib/project.glsl)",
        ("det_nonpositive, with the det fix alone: quad 0.353 (mid - root cancelled to 0: a quad "
         "of zero width)",
         "near_tiny, det overflowing to inf: lam2 = inf, quad axes NaN")),
    Fix("eigenvalue discriminant as ((a - c) / 2)^2 + b^2 where mid^2 - det overflows; "
        "reference radius capped at 2^52 px before the int64 cast",
        "discriminant, reference_radius (project.py, shaders/lib/project.glsl)",
        ("near_tiny: quad 0.295, reference32 0.295 (inf - inf = NaN radius, cast to int64 as "
         "garbage, the veil splat dropped; NumPy overflow and invalid-cast warnings); the tile "
         "renderer passed only because GLSL's max(0.1, NaN) happened to return 0.1",)),
    Fix("quad half-axes shortened to |mean - viewport centre| + |viewport| (covers the same "
        "pixels)", "emit_corner (shaders/lib/quad_emit.glsl)",
        ("near_tiny, after the fixes above: quad 0.295 (a 6e10 px quad, NDC ~1e9, lost by "
         "llvmpipe's clipping)",)),
    Fix("longitude 0 at an exact pole (and for the ODS eye there): GLSL's atan(0, 0) is undefined",
        "project_mean, eye_space (shaders/cameras/fisheye.glsl, equirect.glsl)",
        ("equirect_poles: quad 0.342 (llvmpipe's atan(0, 0) moved a pole band's centre and "
         "with it the half-turn clip; NumPy's arctan2(0, 0) = 0)",)),
    Fix("the CPU renderer counts a positive power as 0 (the conic is positive definite, so it "
        "is rounding) instead of skipping the pixel", "_blend_row (renderers/_cpu_raster.py)",
        ("det_nonpositive: cpu 0.252 (on the axis of a needle whose conic cancels, its fused "
         "multiply-adds left the power 1 ulp above 0 at two pixels, and the needle was skipped "
         "there)",)),
)

// Camera uniforms shared by every stage (splatgl.cameras.view.View.uniforms gives their values),
// then the camera model's piece: cameras/<CAMERA_MODEL>.glsl (its own uniforms, project_mean,
// jacobian, in_view, view_depth; splatgl/cameras/<model>.py is its twin).  visible_area below
// is the share of each quad that early termination's coverage estimate adds up.
// Twin: splatgl/splatmath/early_stop.py coverage().
uniform mat3 u_view_rot;      // world-to-camera rotation R_cw (OpenCV axes)
uniform vec3 u_view_trans;    // world-to-camera translation t_cw
uniform vec3 u_cam_center;    // camera centre in the scene's own frame (for SH directions)
uniform vec4 u_intrinsics;    // (fx, fy, cx, cy) in pixels (orthographic: pixels per unit)
uniform vec2 u_viewport;      // (width, height) in pixels
uniform vec2 u_tan_fov;       // (tan(fov_x / 2), tan(fov_y / 2)) = (W / 2fx, H / 2fy)
uniform float u_near;         // view z at or below this is culled

// Fragments a quad of `area` pixels with bounding rectangle [lo, hi] puts in the viewport,
// estimated as its area times the share of the rectangle inside (at most the viewport's area;
// 0 for an empty or NaN rectangle).  Early termination's coverage estimate (coverage.comp).
float visible_area(vec2 lo, vec2 hi, float area) {
    vec2 size = hi - lo;
    vec2 inside = max(min(hi, u_viewport) - max(lo, vec2(0.0)), vec2(0.0));
    float rect = size.x * size.y;
    if (!(rect > 0.0) || !(area > 0.0)) return 0.0;
    return min(area * (inside.x * inside.y / rect), u_viewport.x * u_viewport.y);
}

#include "cameras/{CAMERA_MODEL}.glsl"

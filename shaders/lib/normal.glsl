// The normal layer's per-splat normal (splatgl/output/layers.py; NORMAL_OUTPUT): 3DGS the axis
// of the smallest scale (the first of equal ones), 2DGS surfels their normal t_u x t_v =
// R[2]; rotated into camera space by u_view_rot (normalised again: a scene transform's scale
// sits in u_view_rot) and turned towards the camera: negated where n . d > 0, d the direction
// from the camera to the centre p (camera space; (0, 0, 1) for an orthographic camera).
// Twin: splatgl/splatmath/normals.py splat_normals().
// Needs lib/camera.glsl included before it.

vec3 camera_facing(vec3 axis, vec3 p) {
    vec3 n = normalize(u_view_rot * axis);
#ifdef ORTHOGRAPHIC
    vec3 d = vec3(0.0, 0.0, 1.0);
#else
    vec3 d = p;
#endif
    return dot(n, d) > 0.0 ? -n : n;
}

// 3DGS: rot the splat's rotation (scene frame), scale its scales, p its camera-space centre.
vec3 splat_normal(mat3 rot, vec3 scale, vec3 p) {
    int k = (scale.x <= scale.y && scale.x <= scale.z) ? 0 : (scale.y <= scale.z ? 1 : 2);
    return camera_facing(rot[k], p);
}

// 2DGS surfels.
vec3 surfel_normal(mat3 rot, vec3 p) {
    return camera_facing(rot[2], p);
}

// Mesh renderer, fragment stage: the face colour (opaque) and the view z of the surface at the
// pixel centre, for compositing splats under it (splatgl/output/under.py).
// Twin: splatgl/splatmath/mesh.py ray_depth().
in float v_z;
flat in vec3 v_color;
layout(location = 0) out vec4 out_color;
layout(location = 1) out vec4 out_z;

void main() {
    out_color = vec4(v_color, 1.0);
    out_z = vec4(v_z, 0.0, 0.0, 1.0);
}

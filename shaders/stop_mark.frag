// Early termination, mark pass (fragment stage): keeps (writes depth 0 at) the pixels whose
// transmittance T = 1 - A has fallen below T_MIN, the reference's stop threshold (DESIGN.md 2).
// The accumulation target is sampled, never attached: this pass renders into a depth-only
// framebuffer.
// Twin: splatgl/splatmath/early_stop.py stop_mask().
layout(binding = ACCUM_UNIT) uniform sampler2D u_accum;

void main() {
    float alpha = texelFetch(u_accum, ivec2(gl_FragCoord.xy), 0).a;
    if (!(1.0 - alpha < T_MIN)) discard;
}

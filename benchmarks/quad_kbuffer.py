"""Can the quad path have a per-pixel order on this OpenGL?  A k-buffer experiment (docs/fidelity.md).

A per-pixel order in a rasterizer that draws one splat after another needs each pixel to keep a
small sorted buffer of fragments (a k-buffer, as the tile renderer's window) and update it
fragment by fragment with image load/store.  That read-modify-write is only correct if the
fragments of one pixel run one after another in draw order: OpenGL guarantees it only with
fragment shader interlock (GL_ARB_fragment_shader_interlock, NV_fragment_shader_interlock,
INTEL_fragment_shader_ordering).  This script:

1. lists which of those the context has;
2. tests whether this implementation runs a pixel's fragments in draw order anyway: N
   full-screen quads, each fragment updating its pixel with a non-commutative step
   ``v = 3 v + instance + 1`` through image load/store; every pixel must end at the serial
   value (any overlap or reordering changes it);
3. measures what a k-buffer fragment costs against the quad path's plain blended fragment:
   N full-screen layers of random depth, the k-buffer shader inserting each fragment into K
   sorted entries held in image arrays (the nearest blended front to back into an accumulation
   image when K overflow), against a shader that only outputs (c a, a) for the fixed-function
   ONE_MINUS_DST_ALPHA blend; ns per fragment and the ratio.

    python benchmarks/quad_kbuffer.py [--size 512] [--layers 64] [--window 8]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

VERT = """
#version 430
void main() {
    vec2 p = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
"""
INSTANCED_VERT = """
#version 430
flat out int v_layer;
void main() {
    vec2 p = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
    gl_Position = vec4(p, 0.0, 1.0);
    v_layer = gl_InstanceID;
}
"""
ORDER_FRAG = """
#version 430
layout(r32ui, binding = 0) uniform coherent uimage2D u_img;
uniform int u_layer;
#ifdef INSTANCED
flat in int v_layer;
#endif
out vec4 o;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
#ifdef INSTANCED
    int layer = v_layer;
#else
    int layer = u_layer;
#endif
    uint v = imageLoad(u_img, p).x;
    imageStore(u_img, p, uvec4(v * 3u + uint(layer) + 1u));
    o = vec4(0.0);
}
"""
PLAIN_FRAG = """
#version 430
uniform int u_layer;
out vec4 o;
void main() {
    float a = 0.3 + 0.5 * fract(sin(float(u_layer) * 12.9898 + gl_FragCoord.x * 0.01) * 43758.5);
    o = vec4(vec3(0.5, 0.4, 0.3) * a, a);
}
"""
KBUF_FRAG = """
#version 430
#define K %d
layout(r32f, binding = 0) uniform coherent image2DArray u_t;      // K depths per pixel
layout(rgba32f, binding = 1) uniform coherent image2DArray u_c;   // K (rgb, alpha)
layout(rgba32f, binding = 2) uniform coherent image2D u_acc;      // (C, T) front to back
layout(r32ui, binding = 3) uniform coherent uimage2D u_n;         // entries held
uniform int u_layer;
out vec4 o;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    float z = fract(sin(float(u_layer) * 78.233 + gl_FragCoord.y * 0.013) * 43758.5);
    float a = 0.3 + 0.5 * fract(sin(float(u_layer) * 12.9898 + gl_FragCoord.x * 0.01) * 43758.5);
    vec4 c = vec4(0.5, 0.4, 0.3, a);
    float wt[K]; vec4 wc[K];
    int n = int(imageLoad(u_n, p).x);
    for (int i = 0; i < K; ++i) { wt[i] = imageLoad(u_t, ivec3(p, i)).x; wc[i] = imageLoad(u_c, ivec3(p, i)); }
    if (n == K) {                           // full: blend the nearest of the K + 1
        vec4 acc = imageLoad(u_acc, p);
        vec4 front = c; float fz = z;
        if (wt[0] <= z) { front = wc[0]; fz = wt[0];
            for (int i = 0; i < K - 1; ++i) { wt[i] = wt[i + 1]; wc[i] = wc[i + 1]; }
            n -= 1; }
        else { n = -1; }                    // the new fragment itself was the nearest
        acc.rgb += front.rgb * front.a * acc.a;
        acc.a *= 1.0 - front.a;
        imageStore(u_acc, p, acc);
    }
    if (n >= 0) {                           // insert, constant loops (as tile_rasterize.comp)
        int q = 0;
        for (int i = 0; i < K; ++i) q += (i < n && wt[i] <= z) ? 1 : 0;
        for (int i = K - 1; i > 0; --i) if (i > q && i <= n) { wt[i] = wt[i - 1]; wc[i] = wc[i - 1]; }
        for (int i = 0; i < K; ++i) if (i == q) { wt[i] = z; wc[i] = c; }
        n += 1;
    } else { n = K; }
    for (int i = 0; i < K; ++i) { imageStore(u_t, ivec3(p, i), vec4(wt[i])); imageStore(u_c, ivec3(p, i), wc[i]); }
    imageStore(u_n, p, uvec4(uint(n)));
    o = vec4(0.0);
}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--layers", type=int, default=64)
    ap.add_argument("--window", type=int, default=8)
    args = ap.parse_args()
    import moderngl
    from splatgl.gl.context import create_headless_context, renderer_name

    ctx = create_headless_context()
    s, n = args.size, args.layers
    print(f"GL renderer: {renderer_name(ctx)}")
    wanted = ("GL_ARB_fragment_shader_interlock", "GL_NV_fragment_shader_interlock",
              "GL_INTEL_fragment_shader_ordering")
    print("fragment ordering extensions: " + ", ".join(f"{e} {'yes' if e in ctx.extensions else 'no'}"
                                                     for e in wanted))
    fbo = ctx.framebuffer(color_attachments=[ctx.texture((s, s), 4, dtype="f4")])
    fbo.use()
    vao = lambda prog: ctx.vertex_array(prog, [])  # noqa: E731

    # 2. order test: one draw per layer (the quad path's batches), one instanced draw (a batch)
    expect = np.uint32(0)
    with np.errstate(over="ignore"):
        for layer in range(n):
            expect = np.uint32(expect * np.uint32(3) + np.uint32(layer + 1))
    for label, instanced, barrier in (("one draw per layer", False, False),
                                      ("one draw per layer, memory barrier between", False, True),
                                      ("one instanced draw", True, False)):
        src = ORDER_FRAG.replace("#version 430", "#version 430\n#define INSTANCED" if instanced
                                 else "#version 430")
        prog = ctx.program(vertex_shader=INSTANCED_VERT if instanced else VERT, fragment_shader=src)
        img = ctx.texture((s, s), 1, dtype="u4")
        img.write(np.zeros((s, s), np.uint32).tobytes())
        img.bind_to_image(0, read=True, write=True)
        va = vao(prog)
        if instanced:
            va.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=n)
        else:
            for layer in range(n):
                prog["u_layer"].value = layer
                va.render(moderngl.TRIANGLE_STRIP, vertices=4)
                if barrier:
                    ctx.memory_barrier()
        ctx.finish()
        got = np.frombuffer(img.read(), np.uint32)
        print(f"draw order kept per pixel through image load/store, {label}: "
              f"{(got == expect).mean() * 100:.2f}% of {s}x{s} pixels over {n} layers")

    # 3. cost of a k-buffer fragment against a plain blended one
    plain = ctx.program(vertex_shader=VERT, fragment_shader=PLAIN_FRAG)
    kbuf = ctx.program(vertex_shader=VERT, fragment_shader=KBUF_FRAG % args.window)
    t_img = ctx.texture_array((s, s, args.window), 1, dtype="f4")
    c_img = ctx.texture_array((s, s, args.window), 4, dtype="f4")
    acc = ctx.texture((s, s), 4, dtype="f4")
    cnt = ctx.texture((s, s), 1, dtype="u4")

    def run(prog, blend):
        va = vao(prog)
        ctx.enable(moderngl.BLEND) if blend else ctx.disable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE
        best = float("inf")
        for _ in range(3):
            fbo.clear()
            if not blend:
                t_img.write(np.full((args.window, s, s), 1e30, np.float32).tobytes())
                acc.write(np.tile(np.array([0, 0, 0, 1], np.float32), (s, s, 1)).tobytes())
                cnt.write(np.zeros((s, s), np.uint32).tobytes())
                t_img.bind_to_image(0, read=True, write=True)
                c_img.bind_to_image(1, read=True, write=True)
                acc.bind_to_image(2, read=True, write=True)
                cnt.bind_to_image(3, read=True, write=True)
            ctx.finish()
            t0 = time.perf_counter()
            for layer in range(n):
                prog["u_layer"].value = layer
                va.render(moderngl.TRIANGLE_STRIP, vertices=4)
            ctx.finish()
            best = min(best, time.perf_counter() - t0)
        return best * 1e9 / (s * s * n)

    ns_plain, ns_kbuf = run(plain, True), run(kbuf, False)
    print(f"per fragment: plain blend {ns_plain:.1f} ns, k-buffer (K={args.window}) {ns_kbuf:.1f} ns "
          f"({ns_kbuf / ns_plain:.1f}x), {s}x{s}, {n} layers")


if __name__ == "__main__":
    main()

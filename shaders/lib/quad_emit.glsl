// Emits one corner of a splat's quad (triangle strip, gl_VertexID 0..3) and the fragment
// inputs of quad.frag.  With TRIANGLE_PER_SPLAT (QuadRenderer.use_triangles: the
// viewer's drafts), one vertex of a single triangle instead (gl_VertexID 0..2): the equilateral
// triangle circumscribing the ellipse in the axes' frame, which holds every pixel the quad's
// inscribed ellipse holds (the ellipse extent only: the fast extent shades the quad's
// corners).  Measured on llvmpipe:
// 0.84-0.91x the quad's draw on far views of biker and guitar, 1.04-1.17x on donut (a third
// more fragments): the exact frame keeps the quad (docs/interactive.md).  Shared by
// quad.vert (math per vertex) and quad_light.vert (math from the compute pre-pass).
// Twin: none (places a corner from splat_setup.glsl's axes, whose twin is ellipse_axes()).

flat out vec2 v_mean2d;       // pixel centre of the splat
flat out vec3 v_conic;        // (a, b, c) of Sigma'^-1
flat out vec4 v_color;        // (SH colour, opacity)
flat out float v_depth;       // camera-space z of the centre, for the depth layer
#ifdef EXTENT_FAST
out vec2 v_unit;              // corner coordinate in sigmas (identity conic)
#endif
#ifdef NORMAL_OUTPUT
flat out vec3 v_normal;       // camera-space unit normal, for the normal layer
#endif
#ifdef ORDERED_PASS
flat out uint v_index;        // the splat's scene row, for the top-contributor layer
flat out uvec4 v_rect;        // the reference's tile rectangle (lib/tile_rect.glsl)
#endif

const vec4 CULLED = vec4(0.0, 0.0, 2.0, 1.0);  // outside the clip volume: nothing rasterised


void emit_corner(vec2 mean2d, vec2 axis1, vec2 axis2, vec3 con, vec3 color, float opacity,
                 float depth) {
#ifdef TRIANGLE_PER_SPLAT
    // Vertices 2 from the centre at 90, 210 and 330 degrees: the unit circle is inscribed.
    vec2 corner = gl_VertexID == 0 ? vec2(0.0, 2.0)
                : vec2(gl_VertexID == 1 ? -1.7320508075688772 : 1.7320508075688772, -1.0);
#else
    vec2 corner = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
#endif
    // Guard (stress case near_tiny): a splat just past a 1e-8 near plane had quads 6e10 px wide
    // (NDC ~1e9), which llvmpipe's clipping lost (max error 0.30).  A half-axis longer than
    // reach = |mean - viewport centre| + |viewport| covers no more of the viewport (the
    // shortened quad still contains the disc of that radius), so shorten it to that.
    float reach = length(mean2d - 0.5 * u_viewport) + length(u_viewport);
    vec2 shrink = vec2(min(1.0, reach / max(length(axis1), 1e-30)),
                       min(1.0, reach / max(length(axis2), 1e-30)));
    vec2 pixel = mean2d + corner.x * shrink.x * axis1 + corner.y * shrink.y * axis2;
    // Image coordinates map to NDC without a y flip: framebuffer row 0 holds image row 0 (the
    // top), so a plain readback is already top-down and gl_FragCoord.xy = (j + 0.5, i + 0.5).
    gl_Position = vec4(pixel / u_viewport * 2.0 - 1.0, 0.0, 1.0);
    v_mean2d = mean2d;
    v_conic = con;
    v_color = vec4(color, opacity);
    v_depth = depth;
#ifdef EXTENT_FAST
    v_unit = corner * shrink * FAST_CORNER_SIGMAS;
#endif
}

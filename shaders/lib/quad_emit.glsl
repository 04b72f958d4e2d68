// Emits one corner of a splat's quad (triangle strip, gl_VertexID 0..3) and the fragment
// inputs of quad.frag.  Shared by quad.vert (math per vertex) and quad_light.vert (math from
// the compute pre-pass).  With PIECES (early termination's tile clipping) a piece of the splat
// (occlusion_cull.comp) is drawn instead of the whole quad: the same quad, clipped by four
// gl_ClipDistance planes to the piece's tiles, so each pixel gets the fragment the whole quad
// gives it or, off the piece, none.

flat out vec2 v_mean2d;       // pixel centre of the splat
flat out vec3 v_conic;        // (a, b, c) of Sigma'^-1
flat out vec4 v_color;        // (SH colour, opacity)
flat out float v_depth;       // camera-space z of the centre, for the depth layer
#ifdef EXTENT_FAST
out vec2 v_unit;              // corner coordinate in sigmas (identity conic)
#endif
#ifdef PIECES
out float gl_ClipDistance[4];
#endif

const vec4 CULLED = vec4(0.0, 0.0, 2.0, 1.0);  // outside the clip volume: nothing rasterised

// Emits one corner (gl_VertexID 0..3) of the quad mean2d +- axis1 +- axis2, or with PIECES of
// piece = (x0 | x1 << 16, y0 | y1 << 16), tiles inclusive (x = WHOLE_PIECE: the whole quad).
void emit_piece(vec2 mean2d, vec2 axis1, vec2 axis2, vec3 con, vec3 color, float opacity,
                float depth, uvec2 piece) {
    vec2 corner = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
    // Guard (stress case near_tiny): a splat just past a 1e-8 near plane had quads 6e10 px wide
    // (NDC ~1e9), which llvmpipe's clipping lost (max error 0.30).  A half-axis longer than
    // reach = |mean - viewport centre| + |viewport| covers no more of the viewport (the
    // shortened quad still contains the disc of that radius), so shorten it to that.
    float reach = length(mean2d - 0.5 * u_viewport) + length(u_viewport);
    vec2 shrink = vec2(min(1.0, reach / max(length(axis1), 1e-30)),
                       min(1.0, reach / max(length(axis2), 1e-30)));
    vec2 a1 = shrink.x * axis1, a2 = shrink.y * axis2;
    vec2 pixel = mean2d + corner.x * a1 + corner.y * a2;
    vec2 unit = corner;
#ifdef PIECES
    // Clip the quad to the piece's pixel rectangle (tile edges lie between pixel centres).
    if (piece.x != WHOLE_PIECE) {
        vec2 tlo = vec2(piece & 0xFFFFu) * float(TILE_SIZE);
        vec2 thi = vec2((piece >> 16) + 1u) * float(TILE_SIZE);
        gl_ClipDistance[0] = pixel.x - tlo.x;
        gl_ClipDistance[1] = thi.x - pixel.x;
        gl_ClipDistance[2] = pixel.y - tlo.y;
        gl_ClipDistance[3] = thi.y - pixel.y;
    } else {
        gl_ClipDistance[0] = gl_ClipDistance[1] = gl_ClipDistance[2] = gl_ClipDistance[3] = 1.0;
    }
#endif
    // Image coordinates map to NDC without a y flip: framebuffer row 0 holds image row 0 (the
    // top), so a plain readback is already top-down and gl_FragCoord.xy = (j + 0.5, i + 0.5).
    gl_Position = vec4(pixel / u_viewport * 2.0 - 1.0, 0.0, 1.0);
    v_mean2d = mean2d;
    v_conic = con;
    v_color = vec4(color, opacity);
    v_depth = depth;
#ifdef EXTENT_FAST
    v_unit = unit * shrink * FAST_CORNER_SIGMAS;
#endif
}

void emit_corner(vec2 mean2d, vec2 axis1, vec2 axis2, vec3 con, vec3 color, float opacity,
                 float depth) {
    emit_piece(mean2d, axis1, axis2, con, color, opacity, depth, uvec2(WHOLE_PIECE, 0u));
}

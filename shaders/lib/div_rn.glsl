// The correctly rounded float32 quotient (IEEE 754, round to nearest: NumPy's float32 a / b),
// from the device's division, which GLSL only asks to be within 2.5 ulp (llvmpipe's is already
// correctly rounded; a GPU's may not be).  The device order's peak-alpha decision
// (order_cull.comp's peak_keeps) must be the CPU's bit for bit: the same kept splats.
//
// q = Q 2^e > 0 is the correctly rounded a / b (a, b > 0) exactly when m-(q) b < a < m+(q) b,
// with m+-(q) the midpoints between q and its neighbours; a never equals m b (the odd part of
// (2Q + 1) B has 25 bits, A's at most 24).  m+(q) b = (2Q + 1) B 2^(e - 1 + g) with b = B 2^g:
// (2Q + 1) B has at most 49 bits (umulExtended), compared exactly with a = A 2^f.
// Used by: shaders/order_cull.comp.
// Twin: none (the twin is NumPy's float32 division itself; test_quad_device.py checks it)

#include "lib/round_rn.glsl"

// Whether a < m+(q) b, for positive normal floats a, b and q.
bool below_upper_quotient(float q, float a, float b) {
    int eq, ea, eb;
    float mq = frexp(q, eq), ma = frexp(a, ea), mb = frexp(b, eb);
    uint big_q = uint(mq * 16777216.0);          // Q, 24 bits
    uint big_a = uint(ma * 16777216.0);          // A, 24 bits
    uint big_b = uint(mb * 16777216.0);          // B, 24 bits
    uint p_hi, p_lo;
    umulExtended(2u * big_q + 1u, big_b, p_hi, p_lo);
    int s = (ea - 24) - ((eq - 24) - 1 + (eb - 24));   // a = A 2^s, in units of (2Q + 1) B's
    return shifted_below(big_a, s, p_hi, p_lo);
}

// a / b rounded to nearest, from the estimate q0 (within a few ulp).  Zero, subnormal, huge,
// infinite and NaN operands and quotients keep the estimate.
float div_rn_from(float a, float b, float q0) {
    float x = abs(a), y = abs(b), s = abs(q0);
    if (!(x >= 1.0e-30 && x <= 1.0e30 && y >= 1.0e-30 && y <= 1.0e30
          && s >= 1.0e-36 && s <= 1.0e36)) return q0;
    for (int k = 0; k < 4; ++k) {
        if (!below_upper_quotient(s, x, y)) s = next_up(s);                    // above
        else if (below_upper_quotient(next_down(s), x, y)) s = next_down(s);  // below
        else break;
    }
    return (a < 0.0) != (b < 0.0) ? -s : s;
}

float div_rn(float a, float b) { return div_rn_from(a, b, a / b); }

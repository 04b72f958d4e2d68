// The correctly rounded float32 square root (IEEE 754, round to nearest: NumPy's np.sqrt on
// float32), from the device's sqrt, which GLSL only asks to be close (llvmpipe's is already
// correctly rounded; a GPU's may be off by an ulp or two).  The device order's lens keys are
// distances, and an ulp changes the order of two splats: the key must be the CPU's bit for bit.
//
// s is the correctly rounded root of a > 0 exactly when m-(s)^2 < a < m+(s)^2, with m+-(s) the
// midpoints between s and its neighbours (Tuckerman's test; a is never a midpoint's square).
// The squares are compared exactly in integers: s = S 2^e, m+(s) = (2S + 1) 2^(e - 1),
// m+(s)^2 = (2S + 1)^2 2^(2e - 2) (50 bits: umulExtended), a = A 2^f (A < 2^24).
// Used by: shaders/order_cull.comp (CULL_SPHERE).
// Twin: none (the twin is NumPy's float32 np.sqrt itself; test_quad_device_lens.py checks it)

#include "lib/round_rn.glsl"

// Whether a < m+(s)^2, for positive normal floats a and s.
bool below_upper_mid(float s, float a) {
    int es, ea;
    float ms = frexp(s, es), ma = frexp(a, ea);
    uint big_s = uint(ms * 16777216.0);          // S, 24 bits
    uint big_a = uint(ma * 16777216.0);          // A, 24 bits
    int q = (ea - 24) - (2 * (es - 24) - 2);     // a = A 2^q in units of 2^(2e - 2)
    uint p_hi, p_lo;
    umulExtended(2u * big_s + 1u, 2u * big_s + 1u, p_hi, p_lo);
    return shifted_below(big_a, q, p_hi, p_lo);
}

// sqrt(a) rounded to nearest, from the estimate s0 (within a few ulp).  Zero, subnormal,
// infinite and NaN arguments and roots keep the estimate.
float sqrt_rn_from(float a, float s0) {
    if (!(a >= 1.0e-36 && a <= 1.0e36)) return s0;
    float s = s0;
    for (int k = 0; k < 4; ++k) {
        if (!below_upper_mid(s, a)) s = next_up(s);               // a above s's interval
        else if (below_upper_mid(next_down(s), a)) s = next_down(s);  // a below it
        else break;
    }
    return s;
}

float sqrt_rn(float a) { return sqrt_rn_from(a, sqrt(a)); }

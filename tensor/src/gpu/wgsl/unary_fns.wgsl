// Element-wise functions of one tensor (UnaryOp in op.rs; codes in ops/elementwise.rs).

fn tanh_stable(v: f32) -> f32 {
    // tanh through exp(-2|v|) <= 1: no overflow for large |v|.
    let e = exp(-2.0 * abs(v));
    return sign(v) * (1.0 - e) / (1.0 + e);
}

// ln(1 + v), accurate for small v (Goldberg's trick: the rounding of 1 + v cancels out),
// as softplus needs for large negative inputs where e^x is tiny.
fn log1p(v: f32) -> f32 {
    let u = 1.0 + v;
    if u == 1.0 {
        return v;
    }
    return log(u) * v / (u - 1.0);
}

fn sigmoid(v: f32) -> f32 {
    if v >= 0.0 {
        return 1.0 / (1.0 + exp(-v));
    }
    let e = exp(v);
    return e / (1.0 + e);
}

// x^q for any sign of x: WGSL's pow is undefined for x < 0, so an integer exponent takes the
// sign from |x|^q and the parity of q (as powf does on the CPU); other exponents give NaN.
fn powq(v: f32, q: f32) -> f32 {
    if v >= 0.0 {
        if v == 0.0 {
            if q > 0.0 { return 0.0; }
            if q == 0.0 { return 1.0; }
            return bitcast<f32>(0x7f800000u);
        }
        return pow(v, q);
    }
    if floor(q) != q {
        return bitcast<f32>(0x7fc00000u);
    }
    let m = pow(-v, q);
    if (i32(q) & 1) == 1 { return -m; }
    return m;
}

fn apply(code: u32, v: f32, c0: f32, c1: f32) -> f32 {
    switch code {
        case 0u: { return -v; }
        case 1u: { return exp(v); }
        case 2u: { return log(v); }
        case 3u: { return sqrt(v); }
        case 4u: { return v * v; }
        case 5u: { return tanh_stable(v); }
        case 6u: { return sigmoid(v); }
        case 7u: { return max(v, 0.0); }
        case 8u: { return max(v, 0.0) + log1p(exp(-abs(v))); }
        case 9u: { return abs(v); }
        case 10u: { return powq(v, c0); }
        case 11u: { return min(max(v, c0), c1); }
        case 12u: { return v * c0; }
        default: { return v + c0; }
    }
}

// dy/dx at input v with output w (UnaryOp::derivative).
fn derivative(code: u32, v: f32, w: f32, c0: f32, c1: f32) -> f32 {
    switch code {
        case 0u: { return -1.0; }
        case 1u: { return w; }
        case 2u: { return 1.0 / v; }
        case 3u: { return 1.0 / (2.0 * w); }
        case 4u: { return 2.0 * v; }
        case 5u: { return 1.0 - w * w; }
        case 6u: { return w * (1.0 - w); }
        case 7u: { return select(0.0, 1.0, v > 0.0); }
        case 8u: { return sigmoid(v); }
        case 9u: { return select(select(0.0, -1.0, v < 0.0), 1.0, v > 0.0); }
        case 10u: { return c0 * powq(v, c0 - 1.0); }
        case 11u: { return select(0.0, 1.0, v >= c0 && v <= c1); }
        case 12u: { return c0; }
        default: { return 1.0; }
    }
}


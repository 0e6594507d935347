// The activation of a product's epilogue (matmul.wgsl, matmul_reduce.wgsl): 0 identity,
// 1 relu, 2 tanh.
fn activation(code: u32, v: f32) -> f32 {
    switch code {
        case 1u: { return max(v, 0.0); }
        case 2u: {
            // tanh through exp(-2|v|) <= 1: no overflow for large |v| (as unary_fns.wgsl).
            let e = exp(-2.0 * abs(v));
            return sign(v) * (1.0 - e) / (1.0 + e);
        }
        default: { return v; }
    }
}

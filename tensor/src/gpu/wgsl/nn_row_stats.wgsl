// The mean and 1 / sqrt(var + eps) (biased variance) of the row x[b .. b + n], each sum a
// sum8 sum divided by n as on the CPU (row_stats); eps is parameter 2. Shared by the
// standardize kernels, which both bind the input as `x`.
fn row_stats(b: u32, n: u32) -> vec2<f32> {
    let e = b + n;
    let full = n / 8u;
    let tail = b + full * 8u;
    let nf = f32(n);
    // mean
    var lo = vec4<f32>(0.0);
    var hi = vec4<f32>(0.0);
    for (var k = b; k < tail; k += 8u) {
        lo += vec4<f32>(x[k], x[k + 1u], x[k + 2u], x[k + 3u]);
        hi += vec4<f32>(x[k + 4u], x[k + 5u], x[k + 6u], x[k + 7u]);
    }
    var s = sum8_combine(lo, hi);
    for (var k = tail; k < e; k++) {
        s += x[k];
    }
    let mean = s / nf;
    // biased variance
    lo = vec4<f32>(0.0);
    hi = vec4<f32>(0.0);
    for (var k = b; k < tail; k += 8u) {
        let a = vec4<f32>(x[k], x[k + 1u], x[k + 2u], x[k + 3u]) - mean;
        let h = vec4<f32>(x[k + 4u], x[k + 5u], x[k + 6u], x[k + 7u]) - mean;
        lo += a * a;
        hi += h * h;
    }
    s = sum8_combine(lo, hi);
    for (var k = tail; k < e; k++) {
        let d = x[k] - mean;
        s += d * d;
    }
    return vec2<f32>(mean, 1.0 / sqrt(s / nf + pf(2u)));
}

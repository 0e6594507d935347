// y = (x - mean) / sqrt(var + eps) over rows of length n (n >= 1), one thread per row; mean
// and the biased variance are sum8 sums divided by n, as on the CPU (row_stats).
// p = [rows, n, eps bits].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> y: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let r = linear_id(wg, nwg, li);
    if r >= p[0] { return; }
    let n = p[1];
    let b = r * n;
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
    let inv = 1.0 / sqrt(s / nf + pf(2u));
    for (var k = b; k < e; k++) {
        y[k] = (x[k] - mean) * inv;
    }
}

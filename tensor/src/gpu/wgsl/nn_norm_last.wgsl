// out[r] = sqrt(sum8(x[r, k]^2) + eps) over rows of length n (n >= 1), one thread per row.
// p = [rows, n, eps bits].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let r = linear_id(wg, nwg, li);
    if r >= p[0] { return; }
    let n = p[1];
    let b = r * n;
    let full = n / 8u;
    var lo = vec4<f32>(0.0);
    var hi = vec4<f32>(0.0);
    for (var c = 0u; c < full; c++) {
        let k = b + c * 8u;
        let a = vec4<f32>(x[k], x[k + 1u], x[k + 2u], x[k + 3u]);
        let h = vec4<f32>(x[k + 4u], x[k + 5u], x[k + 6u], x[k + 7u]);
        lo += a * a;
        hi += h * h;
    }
    var s = sum8_combine(lo, hi);
    for (var k = b + full * 8u; k < b + n; k++) {
        s += x[k] * x[k];
    }
    out[r] = sqrt(s + pf(2u));
}

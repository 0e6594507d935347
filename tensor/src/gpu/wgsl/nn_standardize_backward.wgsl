// Gradient of standardize over rows of length n (n >= 1), one thread per row: with
// inv = 1 / sqrt(var + eps) recomputed from x, dx = inv * (g - mean(g) - y * mean(g * y)),
// every mean a sum8 sum divided by n, as on the CPU.
// p = [rows, n, eps bits].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read> y: array<f32>;
@group(0) @binding(3) var<storage, read> g: array<f32>;
@group(0) @binding(4) var<storage, read_write> dx: array<f32>;

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
    let inv = row_stats(b, n).y;
    // mean(g) and mean(g * y)
    var glo = vec4<f32>(0.0);
    var ghi = vec4<f32>(0.0);
    var plo = vec4<f32>(0.0);
    var phi = vec4<f32>(0.0);
    for (var k = b; k < tail; k += 8u) {
        let ga = vec4<f32>(g[k], g[k + 1u], g[k + 2u], g[k + 3u]);
        let gh = vec4<f32>(g[k + 4u], g[k + 5u], g[k + 6u], g[k + 7u]);
        glo += ga;
        ghi += gh;
        plo += ga * vec4<f32>(y[k], y[k + 1u], y[k + 2u], y[k + 3u]);
        phi += gh * vec4<f32>(y[k + 4u], y[k + 5u], y[k + 6u], y[k + 7u]);
    }
    var sg = sum8_combine(glo, ghi);
    var sgy = sum8_combine(plo, phi);
    for (var k = tail; k < e; k++) {
        sg += g[k];
        sgy += g[k] * y[k];
    }
    let mg = sg / nf;
    let mgy = sgy / nf;
    for (var k = b; k < e; k++) {
        dx[k] = inv * (g[k] - mg - y[k] * mgy);
    }
}

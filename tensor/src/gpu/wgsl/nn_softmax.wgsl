// Softmax over rows of length n (n >= 1), one thread per row, as the CPU computes it: the
// row's max, e = exp(x - max) summed in order, then e * (1 / sum).
// p = [rows, n].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> y: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let r = linear_id(wg, nwg, li);
    if r >= p[0] { return; }
    let n = p[1];
    let b = r * n;
    var mx = x[b];
    for (var k = 1u; k < n; k++) {
        mx = max(mx, x[b + k]);
    }
    var s = 0.0;
    for (var k = 0u; k < n; k++) {
        let e = exp(x[b + k] - mx);
        y[b + k] = e;
        s += e;
    }
    let inv = 1.0 / s;
    for (var k = 0u; k < n; k++) {
        y[b + k] = y[b + k] * inv;
    }
}

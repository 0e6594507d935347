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
    let st = row_stats(b, n);
    let mean = st.x;
    let inv = st.y;
    for (var k = b; k < e; k++) {
        y[k] = (x[k] - mean) * inv;
    }
}

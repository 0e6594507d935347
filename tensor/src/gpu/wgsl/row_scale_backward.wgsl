// Both gradients of y = a * b (or a / b) where b holds one value per row of a (rows of m
// values, e.g. a vector block divided by its norm), in one launch: threads [0, na) write
// ga, the next `rows` threads one gb each, with its row's reduction inside (no broadcast
// temporaries, no separate reduction). The rules and summation order of
// kernels/elementwise.rs's row_scale_backward:
//   ga = g s with s = 1 / b[r] (div) or b[r];
//   gb[r] = sum_row(g a) in eight interleaved partial sums, then -sum / (b[r] b[r]) (div).
// p = [n (elements of a), rows, m, div, na (n when ga is wanted, else 0), want b].
// An unwanted gradient's binding is a one-element placeholder that is never written.
@group(0) @binding(1) var<storage, read> g: array<f32>;
@group(0) @binding(2) var<storage, read> a: array<f32>;
@group(0) @binding(3) var<storage, read> b: array<f32>;
@group(0) @binding(4) var<storage, read_write> ga: array<f32>;
@group(0) @binding(5) var<storage, read_write> gb: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    let m = p[2];
    let div = p[3] != 0u;
    let na = p[4];
    if t < na {
        let bv = b[t / m];
        var s = bv;
        if div { s = 1.0 / bv; }
        ga[t] = g[t] * s;
        return;
    }
    let r = t - na;
    if p[5] == 0u || r >= p[1] { return; }
    let start = r * m;
    var acc: array<f32, 8>;
    for (var l = 0u; l < 8u; l++) { acc[l] = 0.0; }
    let whole = m - m % 8u;
    for (var c = 0u; c < whole; c += 8u) {
        for (var l = 0u; l < 8u; l++) {
            acc[l] = acc[l] + g[start + c + l] * a[start + c + l];
        }
    }
    var sum = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (var c = whole; c < m; c++) {
        sum = sum + g[start + c] * a[start + c];
    }
    let bv = b[r];
    if div { sum = -sum / (bv * bv); }
    gb[r] = sum;
}

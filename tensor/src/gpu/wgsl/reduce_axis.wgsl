// out[o, c, i] = reduction over k in chunk c of x[o, k, i], k in increasing order.
// p = [outer, len, inner, chunk, chunks, op (0 sum, 1 max), scale bits].
// The scale multiplies the result (1/len for a mean, applied once at the last stage).
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    let len = p[1];
    let inner = p[2];
    let chunk = p[3];
    let chunks = p[4];
    if t >= p[0] * chunks * inner { return; }
    let i = t % inner;
    let c = (t / inner) % chunks;
    let o = t / (inner * chunks);
    let k0 = c * chunk;
    let k1 = min(k0 + chunk, len);
    var acc = 0.0;
    if p[5] == 1u {
        acc = bitcast<f32>(0xff800000u);
    }
    for (var k = k0; k < k1; k = k + 1u) {
        let v = x[(o * len + k) * inner + i];
        if p[5] == 1u {
            if v > acc { acc = v; }
        } else {
            acc = acc + v;
        }
    }
    out[t] = acc * pf(6u);
}

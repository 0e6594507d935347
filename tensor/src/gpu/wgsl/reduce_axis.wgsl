// out[o, c, i] = reduction over k in chunk c of x[o, k, i].
// p = [outer, len, inner, chunk, chunks, op (0 sum, 1 max), scale bits, lanes, lanes_fast].
// The scale multiplies the result (1/len for a mean, applied once at the last stage).
//
// A workgroup's 256 threads reduce W = 256 / lanes consecutive outputs, `lanes` threads
// each (ops/reduce.rs chooses lanes, a power of two, from the shape alone). Lane r of output
// q takes the entries k0 + r, k0 + r + lanes, ... of its output in increasing order; the
// lanes' partials are then combined in a fixed tree (lane r with lane r + s for s = lanes / 2,
// ..., 1). The order depends on the shape only, so the bits do not change from run to run.
// The reads are coalesced: neighbouring threads are neighbouring outputs (q = li % W), which
// read neighbouring i, or, when the reduced entries are contiguous (inner = 1, lanes_fast),
// neighbouring lanes of one output (r = li % lanes), which read neighbouring k.
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

var<workgroup> partial: array<f32, 256>;

fn combine(acc: f32, v: f32, is_max: bool) -> f32 {
    if is_max {
        if v > acc { return v; }
        return acc;
    }
    return acc + v;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let len = p[1];
    let inner = p[2];
    let chunk = p[3];
    let chunks = p[4];
    let is_max = p[5] == 1u;
    let lanes = p[7];
    let w = 256u / lanes;
    var q = li % w;
    var r = li / w;
    var lane_step = w;
    if p[8] == 1u {
        q = li / lanes;
        r = li % lanes;
        lane_step = 1u;
    }
    let t = (wg.x + wg.y * nwg.x) * w + q;
    let outputs = p[0] * chunks * inner;
    var acc = 0.0;
    if is_max {
        acc = bitcast<f32>(0xff800000u);
    }
    if t < outputs {
        let i = t % inner;
        let c = (t / inner) % chunks;
        let o = t / (inner * chunks);
        let k1 = min(c * chunk + chunk, len);
        for (var k = c * chunk + r; k < k1; k = k + lanes) {
            acc = combine(acc, x[(o * len + k) * inner + i], is_max);
        }
    }
    partial[li] = acc;
    workgroupBarrier();
    for (var s = lanes / 2u; s > 0u; s = s / 2u) {
        if r < s {
            partial[li] = combine(partial[li], partial[li + s * lane_step], is_max);
        }
        workgroupBarrier();
    }
    if r == 0u && t < outputs {
        out[t] = partial[li] * pf(6u);
    }
}

// out[o, j, i] = x[o, idx[j], i] (index_select along an axis split as (outer, n, inner)).
// p = [total = outer * m * inner, n, m, inner]. Values are copied as u32 words, so every bit
// (NaN payloads, subnormals) is kept.
@group(0) @binding(1) var<storage, read> x: array<u32>;
@group(0) @binding(2) var<storage, read> idx: array<u32>;
@group(0) @binding(3) var<storage, read_write> out: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    if t >= p[0] { return; }
    let n = p[1];
    let m = p[2];
    let inner = p[3];
    let i = t % inner;
    let oj = t / inner;
    let j = oj % m;
    let o = oj / m;
    out[t] = x[(o * n + idx[j]) * inner + i];
}

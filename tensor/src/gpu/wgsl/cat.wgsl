// Concatenation of up to six parts along an axis in one launch: the parts agree on the dims
// before the axis (`outer` blocks) and after it (`inner` values), part j holds len_j entries
// of the axis. This launch writes the output's entries [dst_start, dst_start + chunk) of an
// axis of `total`, where the parts lie one after another (a longer list is cut into chunks
// of six, a launch each). Thread t is one output value; a copy, so the bits are the parts'.
// p = [outer, total, inner, dst_start, chunk, parts, end_0 .. end_5] with end_j the entry of
// the chunk where part j ends (end_{parts-1} = chunk). Unused slots repeat part 0.
@group(0) @binding(1) var<storage, read> x0: array<f32>;
@group(0) @binding(2) var<storage, read> x1: array<f32>;
@group(0) @binding(3) var<storage, read> x2: array<f32>;
@group(0) @binding(4) var<storage, read> x3: array<f32>;
@group(0) @binding(5) var<storage, read> x4: array<f32>;
@group(0) @binding(6) var<storage, read> x5: array<f32>;
@group(0) @binding(7) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    let inner = p[2];
    let chunk = p[4];
    if t >= p[0] * chunk * inner { return; }
    let i = t % inner;
    let k = (t / inner) % chunk;
    let o = t / (inner * chunk);
    var j = 0u;
    while j + 1u < p[5] && k >= p[6u + j] { j++; }
    var begin = 0u;
    if j > 0u { begin = p[5u + j]; }
    let len = p[6u + j] - begin;
    let s = (o * len + k - begin) * inner + i;
    var v: f32;
    switch j {
        case 0u: { v = x0[s]; }
        case 1u: { v = x1[s]; }
        case 2u: { v = x2[s]; }
        case 3u: { v = x3[s]; }
        case 4u: { v = x4[s]; }
        default: { v = x5[s]; }
    }
    out[(o * p[1] + p[3] + k) * inner + i] = v;
}

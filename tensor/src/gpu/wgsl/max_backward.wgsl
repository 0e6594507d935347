// dx[o, k, i] = g[o, i] at the first k where x equals the maximum y[o, i], 0 elsewhere.
// p = [outer, len, inner].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read> y: array<f32>;
@group(0) @binding(3) var<storage, read> g: array<f32>;
@group(0) @binding(4) var<storage, read_write> dx: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    let len = p[1];
    let inner = p[2];
    if t >= p[0] * inner { return; }
    let i = t % inner;
    let o = t / inner;
    var found = false;
    for (var k = 0u; k < len; k = k + 1u) {
        let q = (o * len + k) * inner + i;
        if !found && x[q] == y[t] {
            dx[q] = g[t];
            found = true;
        } else {
            dx[q] = 0.0;
        }
    }
}

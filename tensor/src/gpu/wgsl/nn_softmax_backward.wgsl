// Gradient of softmax over rows of length n (n >= 1), one thread per row:
// dx = y * (g - dot(g, y)), the dot summed in order as the CPU does.
// p = [rows, n].
@group(0) @binding(1) var<storage, read> y: array<f32>;
@group(0) @binding(2) var<storage, read> g: array<f32>;
@group(0) @binding(3) var<storage, read_write> dx: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let r = linear_id(wg, nwg, li);
    if r >= p[0] { return; }
    let n = p[1];
    let b = r * n;
    var dot = y[b] * g[b];
    for (var k = 1u; k < n; k++) {
        dot += y[b + k] * g[b + k];
    }
    for (var k = 0u; k < n; k++) {
        dx[b + k] = y[b + k] * (g[b + k] - dot);
    }
}

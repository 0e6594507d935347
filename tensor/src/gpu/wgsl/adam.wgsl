// One Adam step (torch.optim.Adam without weight decay), element by element, into new
// buffers: m' = b1 m + (1-b1) g, v' = b2 v + (1-b2) g^2,
// p' = p - lr (m' c1) / (sqrt(v' c2) + eps), with c1 = 1/(1-b1^t), c2 = 1/(1-b2^t).
// p = [n, lr, b1, b2, c1, c2, eps, clip, lo, hi] (constants as f32 bits): when clip is 1,
// g is first clipped to [lo, hi] as the clamp op does (unary_fns.wgsl).
@group(0) @binding(1) var<storage, read> param: array<f32>;
@group(0) @binding(2) var<storage, read> grad: array<f32>;
@group(0) @binding(3) var<storage, read> m: array<f32>;
@group(0) @binding(4) var<storage, read> v: array<f32>;
@group(0) @binding(5) var<storage, read_write> param_out: array<f32>;
@group(0) @binding(6) var<storage, read_write> m_out: array<f32>;
@group(0) @binding(7) var<storage, read_write> v_out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    if i >= p[0] { return; }
    var g = grad[i];
    if p[7] != 0u {
        g = min(max(g, pf(8u)), pf(9u));
    }
    let b1 = pf(2u);
    let b2 = pf(3u);
    let m1 = b1 * m[i] + (1.0 - b1) * g;
    let v1 = b2 * v[i] + (1.0 - b2) * g * g;
    m_out[i] = m1;
    v_out[i] = v1;
    param_out[i] = param[i] - pf(1u) * (m1 * pf(4u)) / (sqrt(v1 * pf(5u)) + pf(6u));
}

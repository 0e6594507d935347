// Helpers of the row kernels of nnops (kernels/nnops.rs on the CPU).

// The total of sum8's eight interleaved partial sums (kernels/reduce.rs): lanes 0..3 in lo,
// 4..7 in hi, combined as ((a0 + a4) + (a1 + a5)) + ((a2 + a6) + (a3 + a7)). The values left
// over after the last full group of eight are then added one by one, as on the CPU.
fn sum8_combine(lo: vec4<f32>, hi: vec4<f32>) -> f32 {
    let t = lo + hi;
    return (t.x + t.y) + (t.z + t.w);
}

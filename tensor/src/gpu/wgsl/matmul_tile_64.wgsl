// matmul.wgsl with 64 x 64 output tiles: 4 x 4 outputs per thread.
const MICRO_M: u32 = 4u;

// matmul.wgsl with 128 x 64 output tiles: 8 x 4 outputs per thread.
const MICRO_M: u32 = 8u;

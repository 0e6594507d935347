//! Cross-crate tests (gradient checks and equivariance through whole models, end-to-end
//! training smoke tests) live in `tests/tests/`. This library is intentionally empty.

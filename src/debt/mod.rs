//! DEBT: an embedded wavelet image codec for links of a few kbit/s (work in progress).
pub mod coder;
pub mod rangecoder;
pub mod wavelet;

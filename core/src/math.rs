//! Float maths for core, through `libm` only.
//!
//! `f64::sqrt` and friends compile in host tests but do not exist on `thumbv7em` without std,
//! and libm gives the same bits on every target, which the determinism guarantee (host run ==
//! bare-metal run, bit for bit) depends on. Every transcendental call in core goes through here.

/// Square root (f64).
#[inline]
pub fn sqrt(x: f64) -> f64 {
    libm::sqrt(x)
}
/// Square root (f32).
#[inline]
pub fn sqrtf(x: f32) -> f32 {
    libm::sqrtf(x)
}
/// Sine (f64).
#[inline]
pub fn sin(x: f64) -> f64 {
    libm::sin(x)
}
/// Cosine (f64).
#[inline]
pub fn cos(x: f64) -> f64 {
    libm::cos(x)
}
/// Arc cosine (f64).
#[inline]
pub fn acos(x: f64) -> f64 {
    libm::acos(x)
}
/// Four-quadrant arc tangent (f64).
#[inline]
pub fn atan2(y: f64, x: f64) -> f64 {
    libm::atan2(y, x)
}
/// Four-quadrant arc tangent (f32).
#[inline]
pub fn atan2f(y: f32, x: f32) -> f32 {
    libm::atan2f(y, x)
}
/// Absolute value (f64); plain bit operation, listed here so callers need one import.
#[inline]
pub fn abs(x: f64) -> f64 {
    libm::fabs(x)
}
/// Round half away from zero (f32).
#[inline]
pub fn roundf(x: f32) -> f32 {
    libm::roundf(x)
}
/// Floor (f32).
#[inline]
pub fn floorf(x: f32) -> f32 {
    libm::floorf(x)
}
/// Exponential (f64).
#[inline]
pub fn exp(x: f64) -> f64 {
    libm::exp(x)
}
/// Natural logarithm (f64).
#[inline]
pub fn ln(x: f64) -> f64 {
    libm::log(x)
}
/// Sine (f32).
#[inline]
pub fn sinf(x: f32) -> f32 {
    libm::sinf(x)
}
/// Cosine (f32).
#[inline]
pub fn cosf(x: f32) -> f32 {
    libm::cosf(x)
}

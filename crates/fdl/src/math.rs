//! The few `f64` functions the crate needs: `std`'s with the feature `std`
//! (so seeded fault injection draws the same numbers as before), `libm`'s
//! without it (`core` has no transcendental functions).

#[cfg(feature = "std")]
pub(crate) fn ln(x: f64) -> f64 {
    x.ln()
}
#[cfg(not(feature = "std"))]
pub(crate) fn ln(x: f64) -> f64 {
    libm::log(x)
}

#[cfg(feature = "std")]
pub(crate) fn ln_1p(x: f64) -> f64 {
    x.ln_1p()
}
#[cfg(not(feature = "std"))]
pub(crate) fn ln_1p(x: f64) -> f64 {
    libm::log1p(x)
}

#[cfg(feature = "std")]
pub(crate) fn floor(x: f64) -> f64 {
    x.floor()
}
#[cfg(not(feature = "std"))]
pub(crate) fn floor(x: f64) -> f64 {
    libm::floor(x)
}

#[cfg(feature = "std")]
pub(crate) fn round(x: f64) -> f64 {
    x.round()
}
#[cfg(not(feature = "std"))]
pub(crate) fn round(x: f64) -> f64 {
    libm::round(x)
}

//! Numbers that native code (f64) and a program (`Value`) both compute
//! with, so that a formula is written once, generic over `Real`, and run
//! natively or built into a renderer's program (issue 42; Mitsuba templates
//! its plugins on `Float` the same way). Each operation maps to the one of
//! the same name on f64 and on `Value` (one program instruction), in the
//! order the formula writes them: the program of a generic formula is the
//! one written by hand before, the native values those of the f64 code.

use super::builder::{Mask, Value};
use std::ops::{Add, BitAnd, Div, Mul, Sub};

/// A number of a formula written once (`f64` natively, `Value` in a
/// program).
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
{
    /// A comparison's or a check's outcome (`bool` natively).
    type Mask: Copy + BitAnd<Output = Self::Mask>;
    /// The constant `x` in the computation `self` belongs to.
    fn constant(self, x: f64) -> Self;
    fn sqrt(self) -> Self;
    fn ln(self) -> Self;
    fn exp(self) -> Self;
    fn max(self, other: f64) -> Self;
    fn min(self, other: f64) -> Self;
    fn clamp(self, lo: f64, hi: f64) -> Self;
    fn abs(self) -> Self;
    fn floor(self) -> Self;
    fn atan2(self, x: Self) -> Self;
    /// Neither NaN nor infinite.
    fn finite(self) -> Self::Mask;
    /// self > x (false for NaN).
    fn gt(self, x: f64) -> Self::Mask;
    /// self >= x (false for NaN).
    fn ge(self, x: f64) -> Self::Mask;
    /// self < x (false for NaN).
    fn lt(self, x: f64) -> Self::Mask;
    /// self <= x (false for NaN).
    fn le(self, x: f64) -> Self::Mask;
    /// `a` where `mask` holds, else `b`.
    fn select(mask: Self::Mask, a: Self, b: Self) -> Self;
}

impl Real for f64 {
    type Mask = bool;
    fn constant(self, x: f64) -> f64 {
        x
    }
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
    fn ln(self) -> f64 {
        f64::ln(self)
    }
    fn exp(self) -> f64 {
        f64::exp(self)
    }
    fn max(self, other: f64) -> f64 {
        f64::max(self, other)
    }
    fn min(self, other: f64) -> f64 {
        f64::min(self, other)
    }
    fn clamp(self, lo: f64, hi: f64) -> f64 {
        f64::clamp(self, lo, hi)
    }
    fn abs(self) -> f64 {
        f64::abs(self)
    }
    fn floor(self) -> f64 {
        f64::floor(self)
    }
    fn atan2(self, x: f64) -> f64 {
        f64::atan2(self, x)
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
    fn gt(self, x: f64) -> bool {
        self > x
    }
    fn ge(self, x: f64) -> bool {
        self >= x
    }
    fn lt(self, x: f64) -> bool {
        self < x
    }
    fn le(self, x: f64) -> bool {
        self <= x
    }
    fn select(mask: bool, a: f64, b: f64) -> f64 {
        if mask {
            a
        } else {
            b
        }
    }
}

impl<'a> Real for Value<'a> {
    type Mask = Mask<'a>;
    fn constant(self, x: f64) -> Value<'a> {
        self.builder().c(x)
    }
    fn sqrt(self) -> Value<'a> {
        Value::sqrt(self)
    }
    fn ln(self) -> Value<'a> {
        Value::ln(self)
    }
    fn exp(self) -> Value<'a> {
        Value::exp(self)
    }
    fn max(self, other: f64) -> Value<'a> {
        Value::max(self, other)
    }
    fn min(self, other: f64) -> Value<'a> {
        Value::min(self, other)
    }
    fn clamp(self, lo: f64, hi: f64) -> Value<'a> {
        Value::clamp(self, lo, hi)
    }
    fn abs(self) -> Value<'a> {
        Value::abs(self)
    }
    fn floor(self) -> Value<'a> {
        Value::floor(self)
    }
    fn atan2(self, x: Value<'a>) -> Value<'a> {
        Value::atan2(self, x)
    }
    fn finite(self) -> Mask<'a> {
        Value::finite(self)
    }
    fn gt(self, x: f64) -> Mask<'a> {
        Value::gt(self, x)
    }
    fn ge(self, x: f64) -> Mask<'a> {
        Value::ge(self, x)
    }
    fn lt(self, x: f64) -> Mask<'a> {
        Value::lt(self, x)
    }
    fn le(self, x: f64) -> Mask<'a> {
        Value::le(self, x)
    }
    fn select(mask: Mask<'a>, a: Value<'a>, b: Value<'a>) -> Value<'a> {
        mask.select(a, b)
    }
}

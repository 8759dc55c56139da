//! The gaussian model's programs for tracing renderers (crate::program,
//! docs/jit.md): the same physics as its native path, as array operations.

use super::Gaussian;
use crate::models::SurfacePrograms;

impl SurfacePrograms for Gaussian {}

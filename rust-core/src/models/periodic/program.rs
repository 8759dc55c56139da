//! The periodic model's programs for tracing renderers (crate::program,
//! docs/jit.md): the same physics as its native path, as array operations.

use super::Periodic;
use crate::models::SurfacePrograms;

impl SurfacePrograms for Periodic {}

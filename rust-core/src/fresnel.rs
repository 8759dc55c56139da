//! fresnel

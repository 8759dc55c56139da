//! Periodic surfaces: gratings and the compact disc. See docs/physics.md,
//! "Periodic surfaces".

//! Fractal (fractional Brownian) surfaces through the universal 2-D stable
//! profile Phi_alpha. See docs/physics.md, "Fractal surfaces".

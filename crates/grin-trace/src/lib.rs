//! The CPU reference tracer: integrators (t-parameter form r'' = n grad n), step policies, boundaries.

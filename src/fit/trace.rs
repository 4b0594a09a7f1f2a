//! Classical tracing (vtracer) as a starting point for refinement.

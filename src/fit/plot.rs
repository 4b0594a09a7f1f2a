//! Line plots (speed against error) drawn with diffsvg's own rasterizer.

//! SVG figures of a run (to be filled in).

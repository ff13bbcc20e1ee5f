//! The simulated dual-clutch transmission (the plant): model + reality effects + sensors, as a
//! pure core `Plant::step(now, inputs) -> outputs`.

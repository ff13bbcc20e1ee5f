//! Pure physics of the dry dual-clutch driveline (paper Sects. 3–5): friction and equivalent
//! radius (4)–(6), flat spring (7)–(10), clutch torque (11)/(13) and its inverse, thermal models
//! (16)/(17), driveline (18)–(22), engine and actuators. No I/O, no clock.

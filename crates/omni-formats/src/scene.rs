//! Scene description for the simulator (in progress).

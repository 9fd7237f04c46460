//! Calibration: receiver (catadioptric camera) and transmitter (light planes).

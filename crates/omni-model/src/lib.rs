//! Sensor models: catadioptric camera models and the polygon-mirror laser transmitter.

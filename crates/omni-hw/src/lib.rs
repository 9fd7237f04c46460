//! Controller protocol (framing, CRC, parsing), host client and a device emulator.

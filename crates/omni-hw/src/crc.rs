//! CRC-16/CCITT-FALSE, the checksum every protocol line carries.
//!
//! Parameters (the "Rocksoft" description firmware authors can check against any CRC catalogue):
//! width 16, polynomial 0x1021, initial value 0xFFFF, input and output not reflected, final XOR
//! 0x0000. Check value: the ASCII bytes `123456789` give 0x29B1.

/// CRC-16/CCITT-FALSE of `bytes` (bitwise; lines are short, so no table is needed).
pub fn crc16_ccitt_false(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= (b as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
        }
    }
    crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalogue_check_value() {
        assert_eq!(crc16_ccitt_false(b"123456789"), 0x29B1);
    }

    #[test]
    fn empty_input_is_the_initial_value() {
        assert_eq!(crc16_ccitt_false(b""), 0xFFFF);
    }

    #[test]
    fn a_single_flipped_bit_changes_the_crc() {
        let line = b"TRG seq=12 enc=1250 facet=0 rev=0 t=123456 las=0,1";
        let good = crc16_ccitt_false(line);
        for i in 0..line.len() {
            for bit in 0..8 {
                let mut bad = line.to_vec();
                bad[i] ^= 1 << bit;
                assert_ne!(crc16_ccitt_false(&bad), good, "byte {i} bit {bit}");
            }
        }
    }
}

//! Line framing: `BODY*XXXX\n`, where XXXX is the CRC-16/CCITT-FALSE of BODY in upper-case hex.
//!
//! A body is printable ASCII (0x20–0x7E) without `*`; a line holds at most [`MAX_LINE`] bytes
//! before its newline (a `\r` before the `\n` is tolerated). The reader never trusts a line it
//! cannot verify: over-long lines, bytes outside printable ASCII, a missing or malformed CRC and
//! a CRC mismatch all drop the line, and reading resynchronises at the next newline.

use crate::crc::crc16_ccitt_false;

/// Longest accepted line in bytes, excluding the terminating newline but including `*XXXX`.
pub const MAX_LINE: usize = 128;
/// Longest body (the line without its `*XXXX` suffix).
pub const MAX_BODY: usize = MAX_LINE - 5;

/// Why a received line was dropped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LineError {
    /// More than [`MAX_LINE`] bytes before the newline.
    TooLong,
    /// A byte outside printable ASCII, or a `*` inside the body.
    BadByte,
    /// No `*XXXX` suffix.
    MissingCrc,
    /// The CRC does not match the body.
    CrcMismatch { received: u16, computed: u16 },
}

impl std::fmt::Display for LineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LineError::TooLong => write!(f, "line longer than {MAX_LINE} bytes"),
            LineError::BadByte => write!(f, "byte outside printable ASCII"),
            LineError::MissingCrc => write!(f, "no *XXXX checksum"),
            LineError::CrcMismatch { received, computed } => {
                write!(f, "checksum {received:04X} does not match {computed:04X}")
            }
        }
    }
}

/// Frames `body` as one line. Bodies are built from numbers and fixed words; should one carry
/// a byte a body may not (e.g. an echoed value in a `NAK` reason), it is replaced by `?` and the
/// body cut to [`MAX_BODY`], so the line is always valid.
pub fn encode_line(body: &str) -> String {
    let clean: String = body
        .bytes()
        .take(MAX_BODY)
        .map(|b| if (0x20..=0x7E).contains(&b) && b != b'*' { b as char } else { '?' })
        .collect();
    format!("{clean}*{:04X}\n", crc16_ccitt_false(clean.as_bytes()))
}

fn is_valid_body(body: &[u8]) -> bool {
    body.len() <= MAX_BODY && body.iter().all(|&b| (0x20..=0x7E).contains(&b) && b != b'*')
}

/// Verifies one line (without its newline; a trailing `\r` is ignored) and returns its body.
pub fn decode_line(line: &[u8]) -> Result<&str, LineError> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if line.len() > MAX_LINE {
        return Err(LineError::TooLong);
    }
    let star = line.iter().rposition(|&b| b == b'*').ok_or(LineError::MissingCrc)?;
    let (body, suffix) = (&line[..star], &line[star + 1..]);
    if !is_valid_body(body) {
        return Err(LineError::BadByte);
    }
    if suffix.len() != 4 || !suffix.iter().all(|b| b.is_ascii_hexdigit()) {
        return Err(LineError::MissingCrc);
    }
    // Both checks above guarantee ASCII, so these conversions cannot fail.
    let received =
        u16::from_str_radix(std::str::from_utf8(suffix).unwrap_or("X"), 16).map_err(|_| LineError::MissingCrc)?;
    let computed = crc16_ccitt_false(body);
    if received != computed {
        return Err(LineError::CrcMismatch { received, computed });
    }
    std::str::from_utf8(body).map_err(|_| LineError::BadByte)
}

/// Counters of what the reader accepted and dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LineStats {
    pub lines_ok: u64,
    pub crc_errors: u64,
    /// Over-long, non-ASCII or checksum-less lines.
    pub malformed: u64,
}

impl LineStats {
    /// All dropped lines.
    pub fn dropped(&self) -> u64 {
        self.crc_errors + self.malformed
    }
}

/// Incremental line splitter over an unframed byte stream (a serial port delivers arbitrary
/// chunks). Keeps at most [`MAX_LINE`] + 2 bytes of an unfinished line; the rest of an over-long
/// line is discarded up to the next newline.
#[derive(Debug, Default)]
pub struct LineReader {
    partial: Vec<u8>,
    overflowed: bool,
    pub stats: LineStats,
}

impl LineReader {
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds received bytes; appends the body of every verified line to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<String>) {
        for &b in bytes {
            if b == b'\n' {
                self.finish_line(out);
            } else if self.overflowed {
                continue;
            } else if self.partial.len() > MAX_LINE + 1 {
                self.overflowed = true;
                self.partial.clear();
            } else {
                self.partial.push(b);
            }
        }
    }

    fn finish_line(&mut self, out: &mut Vec<String>) {
        let overflowed = std::mem::take(&mut self.overflowed);
        let line = std::mem::take(&mut self.partial);
        if overflowed {
            self.stats.malformed += 1;
            return;
        }
        if line.is_empty() || line == b"\r" {
            return;
        }
        match decode_line(&line) {
            Ok(body) => {
                self.stats.lines_ok += 1;
                out.push(body.to_string());
            }
            Err(LineError::CrcMismatch { .. }) => self.stats.crc_errors += 1,
            Err(_) => self.stats.malformed += 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoded_lines_decode_to_their_body() {
        let line = encode_line("ACK 17");
        assert_eq!(line, format!("ACK 17*{:04X}\n", crc16_ccitt_false(b"ACK 17")));
        assert_eq!(decode_line(line.trim_end().as_bytes()), Ok("ACK 17"));
        let crlf = line.replace('\n', "\r");
        assert_eq!(decode_line(crlf.as_bytes()), Ok("ACK 17"));
    }

    #[test]
    fn encoding_never_produces_an_invalid_line() {
        let line = encode_line(&format!("NAK 3 1 bad*value \u{e9}\n{}", "x".repeat(300)));
        let body = decode_line(line.trim_end().as_bytes()).unwrap();
        assert_eq!(body.len(), MAX_BODY);
        assert!(body.starts_with("NAK 3 1 bad?value ???"), "{body}");
    }

    #[test]
    fn corrupted_lines_are_rejected_with_the_reason() {
        assert_eq!(decode_line(b"ACK 17"), Err(LineError::MissingCrc));
        assert_eq!(decode_line(b"ACK 17*12G4"), Err(LineError::MissingCrc));
        assert!(matches!(decode_line(b"ACK 17*0000"), Err(LineError::CrcMismatch { .. })));
        let good = encode_line("ACK 17");
        let flipped = good.trim_end().replace("17", "18");
        assert!(matches!(decode_line(flipped.as_bytes()), Err(LineError::CrcMismatch { .. })));
        let mut binary = b"AC\x01K 1".to_vec();
        binary.extend_from_slice(format!("*{:04X}", crc16_ccitt_false(b"AC\x01K 1")).as_bytes());
        assert_eq!(decode_line(&binary), Err(LineError::BadByte));
        let long = "A".repeat(MAX_LINE);
        assert_eq!(decode_line(format!("{long}*0000").as_bytes()), Err(LineError::TooLong));
    }

    #[test]
    fn reader_splits_chunks_and_resynchronises_after_garbage() {
        let mut r = LineReader::new();
        let mut out = Vec::new();
        let stream =
            format!("{}\x00\x7fjunk*FFFF\n{}{}", encode_line("ACK 1"), encode_line("ACK 2"), encode_line("ACK 3"));
        for chunk in stream.as_bytes().chunks(3) {
            r.push(chunk, &mut out);
        }
        assert_eq!(out, vec!["ACK 1", "ACK 2", "ACK 3"]);
        assert_eq!(r.stats.lines_ok, 3);
        assert_eq!(r.stats.malformed, 1);
    }

    #[test]
    fn an_overlong_line_is_dropped_and_the_next_line_survives() {
        let mut r = LineReader::new();
        let mut out = Vec::new();
        r.push(&vec![b'Z'; 5000], &mut out);
        r.push(b"\n", &mut out);
        r.push(encode_line("ACK 9").as_bytes(), &mut out);
        assert_eq!(out, vec!["ACK 9"]);
        assert_eq!(r.stats.malformed, 1);
        assert!(r.partial.capacity() < 1024, "buffer must stay bounded");
    }
}

use std::fmt;

/// An error that says where: the file (or `stdin`), and the field, record or line at fault.
#[derive(Debug)]
pub struct Error {
    /// File path or `stdin`/`stdout`.
    pub source_name: String,
    /// Field, record or line, e.g. `line 12` or `field model.a_mm`; may be empty.
    pub location: String,
    pub message: String,
}

impl Error {
    pub fn new(source_name: impl Into<String>, location: impl Into<String>, message: impl Into<String>) -> Self {
        Error { source_name: source_name.into(), location: location.into(), message: message.into() }
    }

    /// An I/O error on a file.
    pub fn io(source_name: impl Into<String>, err: &std::io::Error) -> Self {
        Error::new(source_name, "", err.to_string())
    }

    /// Whether the error is a closed downstream pipe (a clean exit for a Unix tool).
    pub fn is_broken_pipe(&self) -> bool {
        self.message.contains("Broken pipe")
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.location.is_empty() {
            write!(f, "{}: {}", self.source_name, self.message)
        } else {
            write!(f, "{}: {}: {}", self.source_name, self.location, self.message)
        }
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;

//! The one error type: a message a user can act on, naming the bad parameter.

use std::fmt;

#[derive(Clone, Debug, PartialEq)]
pub struct StamError {
    pub message: String,
}

impl StamError {
    pub fn new(message: impl Into<String>) -> Self {
        StamError {
            message: message.into(),
        }
    }
}

impl fmt::Display for StamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for StamError {}

//! The one place that encodes and decodes variable-size messages (bincode 2, standard
//! configuration, with a size limit on decoding so a peer cannot make us allocate without
//! bound). Swapping the encoding touches only this module.

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Largest payload accepted from a peer, bytes.
pub const MAX_MESSAGE_BYTES: usize = 8 * 1024 * 1024;

/// Why a message could not be encoded.
#[derive(Debug, thiserror::Error)]
#[error("cannot encode message: {0}")]
pub struct EncodeError(#[from] bincode::error::EncodeError);

/// Why a message from a peer was refused.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// Longer than [`MAX_MESSAGE_BYTES`].
    #[error("message of {0} bytes exceeds the {MAX_MESSAGE_BYTES}-byte limit")]
    TooLarge(usize),
    /// Not a valid encoding of the expected type (truncated, corrupted, other layout).
    #[error("malformed message: {0}")]
    Malformed(#[from] bincode::error::DecodeError),
    /// Valid, but followed by bytes that belong to nothing.
    #[error("{0} trailing bytes after the message")]
    Trailing(usize),
}

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_MESSAGE_BYTES>()
}

/// Encodes a message.
pub fn encode<T: Serialize>(msg: &T) -> Result<Vec<u8>, EncodeError> {
    Ok(bincode::serde::encode_to_vec(msg, config())?)
}

/// Decodes a whole message: every byte must belong to it.
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, DecodeError> {
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(DecodeError::TooLarge(bytes.len()));
    }
    let (msg, used) = bincode::serde::decode_from_slice(bytes, config())?;
    if used != bytes.len() {
        return Err(DecodeError::Trailing(bytes.len() - used));
    }
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Msg {
        a: u32,
        b: Vec<u64>,
    }

    #[test]
    fn round_trip_and_refusals() {
        let m = Msg {
            a: 7,
            b: vec![1, 2, 3],
        };
        let bytes = encode(&m).unwrap();
        assert_eq!(decode::<Msg>(&bytes).unwrap(), m);
        assert!(matches!(
            decode::<Msg>(&bytes[..bytes.len() - 1]),
            Err(DecodeError::Malformed(_))
        ));
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(matches!(
            decode::<Msg>(&longer),
            Err(DecodeError::Trailing(1))
        ));
    }

    #[test]
    fn huge_length_prefix_is_refused_without_allocating() {
        // A vector claiming u64::MAX elements.
        let bytes = [7u8, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF];
        assert!(decode::<Msg>(&bytes).is_err());
    }
}

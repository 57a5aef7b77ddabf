//! Zero-copy FDL telegram wire format (no I/O, no allocation).
//!
//! Follows the smoltcp `wire` pattern: [`Telegram::parse`] validates a
//! telegram once and returns a borrowed view ([`Telegram`] /
//! [`DataTelegram`]) whose data unit is a slice of the input buffer;
//! [`Telegram::emit`] writes into a caller buffer (or
//! [`Telegram::emit_to`] into a `BytesMut`).
//!
//! ```
//! use profibus_fdl::wire::{Telegram, DataTelegram, FunctionCode, RequestKind};
//! // FDL Status request from master 2 to station 8.
//! let t = Telegram::Data(DataTelegram {
//!     da: 8, sa: 2, fc: FunctionCode::request(RequestKind::FdlStatus),
//!     dsap: None, ssap: None, data: &[], format: None,
//! });
//! let mut buf = [0u8; 8];
//! let n = t.emit(&mut buf).unwrap();
//! assert_eq!(&buf[..n], &[0x10, 0x08, 0x02, 0x49, 0x53, 0x16]);
//! let (parsed, m) = Telegram::parse(&buf[..n]).unwrap();
//! assert_eq!((parsed.format().name(), m), ("SD1", n));
//! ```

mod code_set;
pub mod consts;
mod fc;
mod hex;
mod telegram;

pub use fc::{FunctionCode, RequestKind, ResponseStatus, StationType};
pub use hex::{parse_hex, Hex, HexError};
pub use telegram::{fcs, frame_len, DataTelegram, EmitError, Format, ParseError, Telegram};

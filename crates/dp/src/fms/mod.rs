//! PROFIBUS-FMS (Fieldbus Message Specification, EN 50170 vol. 2 parts
//! 5 and 6): the application layer of the BK3000's DP/FMS mixed mode
//! (BK3000 manual pp. 58–68), sans-IO like the rest of the stack.
//!
//! - [`pdu`]: the FMS PDUs (Initiate, Reject, Status, Identify, Get-OD,
//!   Read, Write, Information-Report; confirmed request/response/error
//!   with invoke ID) and their codec.
//! - [`lli`]: the lower layer interface on master-slave relationships:
//!   client and server state machines (connect, confirmed services,
//!   release, connection monitoring) over FDL SRD.
//! - [`od`]: object descriptions as Get-OD carries them, the OD header,
//!   the standard data types, values in words.
//! - [`client`]: an FMS client as the application of an FDL active
//!   station, and a run of requests on one connection (`dpctl fms`).
//! - [`decode`]: FMS telegrams in words and JSON (`dpctl sniff`).
//!
//! What is confirmed by which public source and what is marked
//! (unverified): the module docs of [`pdu`] and `docs/fms.md`.

pub mod client;
pub mod decode;
pub mod lli;
pub mod od;
pub mod pdu;

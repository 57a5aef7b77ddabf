//! Captures of the line: [`pcap`] files of telegrams (link type 257,
//! PROFIBUS DL), readable by Wireshark and `dpctl report`; [`read`] is
//! the sans-IO reader of such files.

pub mod pcap;
pub mod read;

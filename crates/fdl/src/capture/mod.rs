//! Captures of the line: [`pcap`] files of telegrams (link type 257,
//! PROFIBUS DL), readable by Wireshark and `dpctl sniff --read`.

pub mod pcap;

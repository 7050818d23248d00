//! `motorlink record`: every exchange of the 1 kHz bridge to an MCAP file (ROS 2 messages in CDR,
//! readable by ROS 2 tools and Python `rosbags` / `mcap`) or a CSV file.

pub mod cdr;
pub mod msgs;

//! End-to-end tests of `grin` (vdb).

#![allow(dead_code)]

use std::process::Command;

fn grin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_grin"))
}

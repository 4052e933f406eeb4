//! Hides the non-FMI symbols that dependencies export (see
//! `fmi2-cosim/linker/fmi2-exports.map`), so the binary's dynamic symbol table
//! holds the FMI 2.0 entry points only.

use std::env;
use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let script = manifest.join("../fmi2-cosim/linker/fmi2-exports.map");
    println!("cargo:rerun-if-changed={}", script.display());
    if env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("linux") {
        println!(
            "cargo:rustc-cdylib-link-arg=-Wl,--version-script={}",
            script.display()
        );
    }
}

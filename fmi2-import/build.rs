//! Compiles the variadic logger shim (see c/logger_shim.c).

fn main() {
    println!("cargo:rerun-if-changed=c/logger_shim.c");
    cc::Build::new()
        .file("c/logger_shim.c")
        .warnings_into_errors(true)
        .compile("fmi2_import_logger");
}

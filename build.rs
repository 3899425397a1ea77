//! Tells the crate whether it is being compiled without optimizations (a debug build without
//! a profile override), so the plugin can say why its cloth runs 20–60 times slower there.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(cloth_unoptimized)");
    if std::env::var("OPT_LEVEL").is_ok_and(|level| level == "0") {
        println!("cargo::rustc-cfg=cloth_unoptimized");
    }
    println!("cargo::rerun-if-changed=build.rs");
}

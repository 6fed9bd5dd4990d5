//! Prints the host's values of `arith_check::write` (compare with the AVR image's UART output)
//! to the file `ARITH_HOST_OUT` names, if set (`scripts/avr-arith-check` sets it), and those of
//! `arith_check::write_reid` to `ARITH_HOST_REID_OUT`.
#[test]
fn host_arith_lines() {
    struct S(String);
    impl ufmt::uWrite for S {
        type Error = core::convert::Infallible;
        fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
            self.0.push_str(s);
            Ok(())
        }
    }
    let mut s = S(String::new());
    firmware_diag::arith_check::write(&mut s);
    if let Some(path) = std::env::var_os("ARITH_HOST_OUT") {
        std::fs::write(&path, &s.0).unwrap_or_else(|e| panic!("{}: {e}", path.to_string_lossy()));
    }
    assert!(s.0.ends_with("end\n"));
    let mut r = S(String::new());
    firmware_diag::arith_check::write_reid(&mut r);
    if let Some(path) = std::env::var_os("ARITH_HOST_REID_OUT") {
        std::fs::write(&path, &r.0).unwrap_or_else(|e| panic!("{}: {e}", path.to_string_lossy()));
    }
    assert!(
        r.0.contains("reid coef") && r.0.ends_with("end\n"),
        "{}",
        r.0
    );
}

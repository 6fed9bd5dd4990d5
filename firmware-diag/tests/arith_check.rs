//! Prints the host's values of `arith_check::write` (compare with the AVR image's UART output).
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
    std::fs::write("/tmp/arith/host.txt", &s.0).ok();
    assert!(s.0.ends_with("end\n"));
}

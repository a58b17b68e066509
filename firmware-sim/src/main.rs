//! `fishtrack-firmware-sim`: the Cam-trawl's in-housing processor simulated
//! on the host.

fn main() -> std::process::ExitCode {
    eprintln!("fishtrack-firmware-sim: not built yet");
    std::process::ExitCode::from(2)
}

//! The `talus` binary: the command line with every contact law of the workspace.

fn main() -> std::process::ExitCode {
    talus_cli::main_with(talus::registry())
}

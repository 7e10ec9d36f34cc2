//! The `talus` binary: the command line with every contact law of the workspace.

/// Large blocks on huge pages where the kernel gives them on request (`talus_cli::alloc`).
#[global_allocator]
static ALLOCATOR: talus_cli::alloc::HugePageAllocator = talus_cli::alloc::HugePageAllocator;

fn main() -> std::process::ExitCode {
    talus_cli::main_with(talus::registry())
}

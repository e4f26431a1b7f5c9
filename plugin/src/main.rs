//! The `volscatter` command-line tool. `cargo run --release -- render` renders the embedded
//! default scene.

mod cli;

fn main() {
    std::process::exit(cli::main());
}

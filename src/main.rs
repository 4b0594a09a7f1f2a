//! The `diffsvg` command-line tool; see `diffsvg --help`. A thin layer over the `diffsvg`
//! library: argument parsing, progress display, file naming and exit codes live here.

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}

//! The `diffsvg` command-line tool; see `diffsvg --help`.

fn main() -> std::process::ExitCode {
    diffsvg::cli::main()
}

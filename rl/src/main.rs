//! The `meben` program (being written).

fn main() {
    eprintln!("meben: the command-line program is being written");
    std::process::exit(2);
}

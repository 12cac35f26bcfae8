fn main() {
    println!("makeit4d");
}

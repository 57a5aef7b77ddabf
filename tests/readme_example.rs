//! README.md's library loop is `examples/library_loop.rs` (which cargo
//! builds with the tests): the README's ```rust block must be the
//! example's code below its `// README begin` line, byte for byte.

#[test]
fn readme_shows_the_library_loop_example_as_it_is() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let example = std::fs::read_to_string(root.join("examples/library_loop.rs")).unwrap();
    let code = example
        .split_once("// README begin\n")
        .expect("the example marks where README.md's copy begins")
        .1;
    let block = readme
        .split_once("```rust\n")
        .and_then(|(_, rest)| rest.split_once("```\n"))
        .expect("README.md has a ```rust block")
        .0;
    assert_eq!(
        block, code,
        "README.md's ```rust block differs from examples/library_loop.rs"
    );
}

//! Writes an `.rrd` of the inputs given: `cargo run --release -p scaledp-viewer --example
//! save_rrd -- OUT.rrd PATH…` (what `scaledp view --save` does, without the CLI).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = args.next().ok_or("usage: save_rrd OUT.rrd PATH…")?;
    let paths: Vec<String> = args.collect();
    let s = scaledp_viewer::view(
        &paths,
        scaledp_viewer::ViewOptions::new(),
        &scaledp_viewer::Target::Save(out.into()),
    )?;
    for shown in s.shown {
        println!(
            "{}: {} frames, {:?}",
            shown.name, shown.frames, shown.images
        );
    }
    Ok(())
}

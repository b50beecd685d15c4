//! Milliseconds of each ResNet-18 convolution's forward, input gradient and weight gradient at
//! a training batch's shapes (default: one camera's 128 images of 76×76 and a trunk of width
//! 64, the 84×84 bench's; the recipe's is `128 58 32`):
//!
//! ```sh
//! cargo run --release -p scaledp-policy --example conv_ops -- [images] [crop] [width]
//! ```
fn main() -> scaledp_policy::Result<()> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|s| s.parse().ok())
        .collect();
    let (b, crop) = (
        args.first().copied().unwrap_or(128),
        args.get(1).copied().unwrap_or(76),
    );
    let w = args.get(2).copied().unwrap_or(64);
    let s1 = crop.div_ceil(2).div_ceil(2);
    let (s2, s3) = (s1.div_ceil(2), s1.div_ceil(2).div_ceil(2));
    let s4 = s3.div_ceil(2);
    let layers = [
        (3, w, crop, 7, 2),
        (w, w, s1, 3, 1),
        (w, 2 * w, s1, 3, 2),
        (2 * w, 2 * w, s2, 3, 1),
        (2 * w, 4 * w, s2, 3, 2),
        (4 * w, 4 * w, s3, 3, 1),
        (4 * w, 8 * w, s3, 3, 2),
        (8 * w, 8 * w, s4, 3, 1),
    ];
    let mut total = [0f64; 3];
    for (ci, co, hw, k, s) in layers {
        let t = scaledp_policy::bench::conv_op_ms(b, (ci, co), hw, k, s, 5)?;
        println!(
            "{ci}->{co} {hw}x{hw} k{k} s{s}: forward {:.1} ms, input gradient {:.1} ms, weight gradient {:.1} ms",
            t[0], t[1], t[2]
        );
        total.iter_mut().zip(t).for_each(|(a, v)| *a += v);
    }
    println!(
        "sum: forward {:.1}, input gradient {:.1}, weight gradient {:.1} ms",
        total[0], total[1], total[2]
    );
    Ok(())
}

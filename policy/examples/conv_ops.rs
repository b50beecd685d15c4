//! Milliseconds of each ResNet-18 convolution's forward, input gradient and weight gradient at
//! a training batch's shapes (default: 256 images of 76×76, the 84×84 bench's crops):
//!
//! ```sh
//! cargo run --release -p scaledp-policy --example conv_ops -- [images] [crop]
//! ```
fn main() -> scaledp_policy::Result<()> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|s| s.parse().ok())
        .collect();
    let (b, crop) = (
        args.first().copied().unwrap_or(256),
        args.get(1).copied().unwrap_or(76),
    );
    let s1 = crop.div_ceil(2).div_ceil(2);
    let (s2, s3) = (s1.div_ceil(2), s1.div_ceil(2).div_ceil(2));
    let s4 = s3.div_ceil(2);
    let layers = [
        (3, 64, crop, 7, 2),
        (64, 64, s1, 3, 1),
        (64, 128, s1, 3, 2),
        (128, 128, s2, 3, 1),
        (128, 256, s2, 3, 2),
        (256, 256, s3, 3, 1),
        (256, 512, s3, 3, 2),
        (512, 512, s4, 3, 1),
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

//! `diffsvg compare`: recon logs into one PSNR-against-time chart.

use super::common::{diffsvg, s, scratch, write};

const VOXEL: &str = "iteration,seconds,res,allocated,batch_psnr,test_psnr\n\
50,1.0,64,100,20.0,\n100,2.0,64,100,22.0,24.5\n150,3.0,64,100,23.0,\n200,4.0,64,100,24.0,26.0\n";
const SPLAT: &str = "iteration,seconds,gaussians,sh_degree,view_psnr,test_psnr\n\
100,1.5,1000,0,21.0,23.0\n200,3.5,1200,1,25.0,27.5\n";

#[test]
fn two_logs_make_one_chart() {
    let dir = scratch("compare-two");
    let a = write(&dir, "lego-voxel.log.csv", VOXEL);
    let b = write(&dir, "lego-splat.log.csv", SPLAT);
    let png = dir.join("chart.png");
    let r = diffsvg(&["compare", s(&a), s(&b), "-o", s(&png)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (800, 500));
    let svg = std::fs::read_to_string(dir.join("chart.svg")).unwrap();
    assert!(svg.contains("lego-voxel") && svg.contains("lego-splat"));
}

#[test]
fn a_log_without_test_points_or_columns_is_refused() {
    let dir = scratch("compare-bad");
    let none = write(
        &dir,
        "none.log.csv",
        "iteration,seconds,gaussians,sh_degree,view_psnr,test_psnr\n50,1.0,10,0,20.0,\n",
    );
    let other = write(&dir, "other.csv", "a,b\n1,2\n");
    let nan = write(
        &dir,
        "nan.log.csv",
        "iteration,seconds,test_psnr\n50,NaN,20.0\n",
    );
    for (log, says) in [
        (&none, "no test PSNR"),
        (&other, "no `seconds` column"),
        (&nan, "line 2"),
    ] {
        let png = dir.join("chart.png");
        let r = diffsvg(&["compare", s(log), "-o", s(&png)]);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(s(log)) && err.contains(says), "{err}");
        assert!(!png.exists());
    }
}

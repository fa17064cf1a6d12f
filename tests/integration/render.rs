//! `fleet render` writes the pictures of one frame, and they are valid PNG files.

use std::process::Command;

use tests::{TestRun, binary, run_to_end, small_scenario_toml};

#[test]
fn render_writes_decodable_pictures_and_the_frame_json() {
    let t = TestRun::new("render");
    let scenario = t.write("scenario.toml", &small_scenario_toml(10.0));
    let out_dir = t.dir.join("out");
    let out = run_to_end(
        Command::new(binary("fleet"))
            .args(["render", "--uav", "1", "--time", "2.5", "--scenario"])
            .arg(&scenario)
            .arg("--out")
            .arg(&out_dir),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "fleet render failed: {stderr}");
    for name in ["labels.png", "depth.png", "topview.png"] {
        let path = out_dir.join(name);
        let file = std::fs::File::open(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .unwrap_or_else(|e| panic!("{name} is not a PNG: {e}"));
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader
            .next_frame(&mut buf)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(info.width >= 48 && info.height >= 36, "{name}: {info:?}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("frame.json")).unwrap())
            .unwrap();
    assert_eq!(json["header"]["uav"], 1);
    assert_eq!(json["header"]["step"], 5);
    assert!(json["boxes"].is_array());
}

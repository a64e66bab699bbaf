"""A killed writer's temporary files are removed by the next writer of the folder, and nothing else is."""

from latentrl.preflight import locked_output


def test_the_next_writer_of_an_output_folder_removes_what_killed_writes_left(tmp_path):
    out = tmp_path / "out"
    (out / "motions" / "deeper").mkdir(parents=True)
    left = [out / ".report.json.k2x_9abc.tmp", out / ".paths.png.a1b2c3d4.tmp.png",
            out / "motions" / ".p0.npz.zz00yy11.tmp"]
    kept = [out / ".notes.tmp", out / "keep.tmp", out / "report.json", out / ".report.json.short.tmp",
            out / "motions" / "deeper" / ".p1.npz.zz00yy11.tmp"]  # two levels down: not ours to clean
    for path in left + kept:
        path.write_text("x")
    (out / ".link.json.abcdefgh.tmp").symlink_to(out / "report.json")
    with locked_output(out):
        assert not any(p.exists() for p in left)
        assert all(p.exists() for p in kept)
        assert (out / ".link.json.abcdefgh.tmp").is_symlink() and (out / "report.json").read_text() == "x"

"""The record daemon end to end: simulated MTi-G on a real pty -> driver -> detection -> MCAP.

Everything here is real: the simulated sensor speaks the protocol on a pseudo-terminal,
the driver opens it by path through pyserial, files are MCAP read back with the mcap
reader, .rrd files are read back with rerun's RrdReader.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from support.record_settings import sim_record_settings
from support.run_metadata import run_metadata
from tankdaq.acquire.daemon import RecordDaemon
from tankdaq.acquire.events import Released, Settled
from tankdaq.acquire.listeners import EventLog
from tankdaq.cli import app
from tankdaq.records import DecayEnd
from tankdaq.samples import AXIS_FIELDS
from tankdaq.store.reader import iter_raw_chunks, read_recording
from tankdaq.xsens.column_decoder import to_samples
from tankdaq.xsens.stream_decoder import StreamDecoder
from tankdaq.xsens.timebase import SampleTimeUnwrapper

TICKS_PER_S = 10_000


def _events(recording, kind: str) -> list[dict]:
    return [e for e in recording.events if e["kind"] == kind]


def _decode_raw(path: Path) -> np.ndarray:
    decoder, unwrapper = StreamDecoder(), SampleTimeUnwrapper()
    blocks = [
        to_samples(decoder.feed(raw), unwrapper, host_ns / 1e9) for host_ns, raw in iter_raw_chunks(path)
    ]
    return np.concatenate(blocks)


@pytest.fixture(scope="module")
def three_decays(tmp_path_factory: pytest.TempPathFactory) -> tuple[RecordDaemon, list]:
    out = tmp_path_factory.mktemp("rec")
    settings = sim_record_settings(
        out,
        draft=1.1,
        runs=3,
        viewer="save",
        operator="tester",
        note="three in a row",
        sim_speed=8.0,
        sim_seed=3,
    )
    daemon = RecordDaemon(settings)
    outcomes = daemon.run()
    return daemon, outcomes


@pytest.mark.slow
def test_three_decays_in_one_run_each_a_valid_mcap(three_decays) -> None:
    _, outcomes = three_decays
    assert len(outcomes) == 3
    paths = [o.path for o in outcomes]
    assert len(set(paths)) == 3 and all(p.exists() for p in paths)
    for path in paths:
        assert path.name.startswith("swath_1.1T_roll_8deg_")
        with path.open("rb") as f:
            reader = make_reader(f)
            topics = {c.topic for c in reader.get_summary().channels.values()}
            assert {"/xsens/raw", "/samples", "/events", "/fit"} <= topics
        recording = read_recording(path)
        meta = recording.metadata
        for key in (
            "hull",
            "draft",
            "axis",
            "angle_nominal_deg",
            "angle_initial_deg",
            "release_t_s",
            "sample_rate_hz",
            "device_id",
            "product_code",
            "firmware",
            "software_version",
            "operator",
            "note",
            "hull_length_m",
            "hull_displacement_kg",
        ):
            assert key in meta, key
        assert meta["operator"] == "tester" and meta["draft"] == "1.1T"
        assert abs(abs(float(meta["angle_initial_deg"])) - 8.0) < 1.0
        assert len(_events(recording, "release")) == 1 and len(_events(recording, "settled")) == 1
        assert recording.ended.whole and meta["ended"] == recording.ended.value  # settled (or timed out)
        assert run_metadata(path)["ended"] == recording.ended.value  # as the official reader reads it
        assert recording.fits, "the live fit is stored as it evolves"
        assert recording.attachments, "the run configuration is attached"


@pytest.mark.slow
def test_raw_frames_decode_to_the_decoded_channel(three_decays) -> None:
    _, outcomes = three_decays
    for outcome in outcomes:
        recording = read_recording(outcome.path)
        stored = recording.samples
        redecoded = _decode_raw(outcome.path)
        assert redecoded.size == stored.size
        np.testing.assert_array_equal(redecoded["counter"], stored["counter"])
        np.testing.assert_array_equal(redecoded["ticks"], stored["ticks"])
        for field in ("roll", "pitch", "p", "q", "az"):
            np.testing.assert_allclose(redecoded[field], stored[field], rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_release_within_one_sample_of_the_truth(three_decays) -> None:
    daemon, outcomes = three_decays
    truths = [r for r in daemon.simulator.truth if r.kind == "release"]
    sample_ticks = TICKS_PER_S / 100
    for outcome in outcomes:
        recording = read_recording(outcome.path)
        release = _events(recording, "release")[0]
        first_free_ticks = round(release["data"]["first_free_sample_t_s"] * TICKS_PER_S)
        # the truth's first free sample: the first sample at or after the true release instant
        ticks = recording.samples["ticks"]
        nearest = min(truths, key=lambda r: abs(r.release_ticks - first_free_ticks))
        true_first = int(ticks[np.searchsorted(ticks, nearest.release_ticks)])
        assert abs(first_free_ticks - true_first) <= sample_ticks, (first_free_ticks, true_first)
        # the instant itself, on the device clock, with its standard error: between the last held
        # sample and the first free one, and within a sample and three standard errors of the truth
        se_s = release["data"]["release_se_s"]
        assert 0 < se_s < 2 * sample_ticks / TICKS_PER_S
        first_free_s = release["data"]["first_free_sample_t_s"]
        assert first_free_s - sample_ticks / TICKS_PER_S < release["t_s"] <= first_free_s
        assert abs(release["t_s"] * TICKS_PER_S - nearest.release_ticks) <= sample_ticks


@pytest.mark.slow
def test_pretrigger_and_settle(three_decays) -> None:
    _, outcomes = three_decays
    for outcome in outcomes:
        recording = read_recording(outcome.path)
        t = recording.samples["t"]
        release = _events(recording, "release")[0]
        assert release["t_s"] - t[0] >= 1.9, "about 2 s of pre-trigger before the release"
        angle_deg = np.degrees(recording.samples[AXIS_FIELDS["roll"][0]])
        tail = np.abs(angle_deg[t > t[-1] - 1.0] - release["data"]["still_water_deg"])
        assert tail.max() < 0.75, "recorded until the amplitude is below 0.5 deg (plus sensor noise)"


@pytest.mark.slow
def test_live_fit_converges_to_the_hull_model(three_decays) -> None:
    daemon, outcomes = three_decays
    truth = daemon.simulator.truth[0].coefficients
    for outcome in outcomes:
        fit = outcome.fit
        assert fit is not None and fit.r2_angle > 0.99
        natural_period = 2 * np.pi / np.sqrt(truth["c1"])
        assert abs(fit.natural_period_s - natural_period) / natural_period < 0.02


@pytest.mark.slow
def test_rrd_beside_each_mcap_holds_angle_rate_and_fit(three_decays) -> None:
    from rerun.chunk import RrdReader

    _, outcomes = three_decays
    rrd = outcomes[0].rrd_path
    assert rrd is not None and rrd == outcomes[0].path.with_suffix(".rrd") and rrd.exists()
    entities = {chunk.entity_path for chunk in RrdReader(str(rrd)).stream().to_chunks()}
    assert "/angle/measured" in entities and "/rate/measured" in entities
    assert any(e.startswith("/angle/fits/") for e in entities)
    assert any(e.startswith("/coefficients") for e in entities)


@pytest.mark.slow
def test_replay_redetects_the_release_and_refits(three_decays) -> None:
    from tankdaq.acquire.replay import replay_recording

    _, outcomes = three_decays
    recorded = outcomes[0]
    heard = EventLog()
    replayed = replay_recording(recorded.path, speed=None, viewer="none", listeners=[heard])
    assert len(replayed) == 1
    again = replayed[0]
    (released,) = heard.of(Released)  # the listeners hear replay's events as they hear the daemon's
    assert released.t_s == again.release_t and [e.outcome for e in heard.of(Settled)] == replayed
    assert abs(again.release_t - recorded.release_t) < 0.011
    for term, value in recorded.fit.coefficients.items():
        half_width = abs(recorded.fit.ci95[term][1] - recorded.fit.ci95[term][0]) / 2
        assert abs(again.fit.coefficients[term] - value) <= half_width + 1e-9, term


def _tankdaq(*args: str, **kwargs) -> subprocess.Popen:
    exe = Path(sys.executable).with_name("tankdaq")
    return subprocess.Popen(
        [str(exe), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs
    )


def record_args(port: str, out: Path, *extra: str) -> list[str]:
    """``tankdaq record`` arguments for the swath at T from 8 deg on ``port``, writing into ``out``."""
    return [
        "record",
        "--port",
        port,
        "--hull",
        "swath",
        "--draft",
        "T",
        "--angle",
        "8",
        "--out",
        str(out),
        *extra,
    ]


BAD_INPUTS = [
    (["--hull", "swath", "--port", "sim", "--draft", "1.1X", "--angle", "8"], "draft"),
    (["--hull", "swath", "--port", "sim", "--draft", "T", "--angle", "-3"], "angle"),
    (["--hull", "swath", "--port", "sim", "--draft", "T", "--angle", "abc"], "angle"),
    (["--port", "sim", "--draft", "T", "--angle", "8", "--hull", "titanic"], "hull"),
    (["--hull", "swath", "--port", "sim", "--draft", "T", "--angle", "8", "--axis", "yaw"], "axis"),
    (["--hull", "swath", "--port", "sim", "--draft", "T", "--angle", "8", "--rate", "150"], "rate"),
    (["--hull", "swath", "--port", "sim", "--draft", "T", "--angle", "8", "--viewer", "hologram"], "viewer"),
    (["--hull", "swath", "--port", "sim", "--draft", "T", "--angle", "8", "--model", "b9,c1"], "b9"),
    (["--hull", "swath", "--port", "sim", "--draft", "3T", "--angle", "8"], "draft"),
    (["--draft", "T", "--angle", "8"], "port"),
    (
        ["--hull", "swath", "--port", "/dev/ttyNOPE0", "--draft", "T", "--angle", "8", "--viewer", "none"],
        "/dev/ttyNOPE0",
    ),
]


@pytest.mark.parametrize(("args", "mentions"), BAD_INPUTS)
@pytest.mark.slow
def test_bad_record_input_exit_2_one_line(args: list[str], mentions: str) -> None:
    result = CliRunner().invoke(app, ["record", *args])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert mentions.lower() in result.output.lower()


@pytest.mark.slow
def test_missing_port_in_a_real_process_is_one_line_no_traceback(tmp_path: Path) -> None:
    proc = _tankdaq(*record_args("/dev/ttyNOPE0", tmp_path))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in err
    assert not list(tmp_path.glob("*.mcap"))


@pytest.mark.parametrize(
    ("content", "mentions"), [(b"not an mcap at all", "mcap"), (None, "no such"), (b"", "empty")]
)
@pytest.mark.slow
def test_replay_refuses_what_is_not_a_recording(tmp_path: Path, content: bytes | None, mentions: str) -> None:
    path = tmp_path / "x.mcap"
    if content is not None:
        path.write_bytes(content)
    result = CliRunner().invoke(app, ["replay", str(path), "--viewer", "none", "--speed", "max"])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1


@pytest.mark.slow
def test_json_metadata_is_plain(three_decays) -> None:
    _, outcomes = three_decays
    recording = read_recording(outcomes[0].path)
    config = recording.run_config
    json.dumps(config)
    assert config["record"]["hull"] == "swath"


@pytest.mark.slow
def test_full_disk_stops_with_one_line_and_the_file_recovers(tmp_path: Path) -> None:
    """A real EFBIG: the recorder runs with a file-size limit below one decay's size."""
    import resource

    def small_files() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (120_000, 120_000))

    exe = str(Path(sys.executable).with_name("tankdaq"))
    args = record_args("sim", tmp_path, "--viewer", "none")
    proc = subprocess.run(
        [exe, *args, "--runs", "2", "--sim-speed", "8"],
        capture_output=True,
        text=True,
        timeout=180,
        preexec_fn=small_files,
    )
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("error: disk full writing") and "tankdaq recover" in last
    (cut,) = tmp_path.glob("*.mcap")
    assert read_recording(cut).ended is DecayEnd.CUT  # never closed: no footer
    result = subprocess.run([exe, "recover", str(cut)], capture_output=True, text=True, timeout=60)
    assert result.returncode in (0, 3), result.stderr
    recovered = read_recording(next(tmp_path.glob("*.recovered.mcap")))
    assert recovered.samples.size > 100 and _events(recovered, "release")
    assert recovered.ended is DecayEnd.RECOVERED and recovered.metadata["hull"] == "swath"


@pytest.mark.slow
def test_demo_records_identifies_and_plots(tmp_path: Path) -> None:
    """What `make demo` runs, shortened: one simulated decay, identified against the hull's truth with the
    truth's own terms, asked for by name (the default model is the data's:
    tests/project/test_one_model.py)."""
    demo = ["demo", "--runs", "1", "--sim-speed", "10", "--model", "seed001-eq1", "--seed", "0"]  # one decay
    result = CliRunner().invoke(app, [*demo, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    (said,) = [line for line in result.stderr.splitlines() if line.endswith("given by --model")]
    assert "seed001-eq1" in said
    assert len(list(tmp_path.glob("*.mcap"))) == 1
    assert len(list(tmp_path.glob("*.rrd"))) == 1
    assert len(list(tmp_path.glob("*.png"))) == 1
    verdicts = [line for line in result.output.splitlines() if "95 % interval)" in line]
    assert len(verdicts) == 6, result.output
    assert sum("inside" in line for line in verdicts) >= 5, "the truth lies inside (nearly) every interval"


@pytest.mark.slow
def test_a_legacy_mti_g_is_recorded_and_replayed(tmp_path: Path) -> None:
    """The 2007-era MTi-G speaks only MTData 0x32: recording and replay decode it all the same."""
    from tankdaq.acquire.replay import replay_recording

    settings = sim_record_settings(tmp_path, runs=1, sim_speed=8.0, sim_seed=9, sim_legacy=True)
    daemon = RecordDaemon(settings)
    (outcome,) = daemon.run()
    recording = read_recording(outcome.path)
    assert recording.metadata["legacy_protocol"].lower() == "true"
    truth = next(r for r in daemon.simulator.truth if r.kind == "release")
    release = _events(recording, "release")[0]
    # legacy time is the sample counter times the period; the simulated counter is the scenario's
    # sample index plus the seed, so the true first free sample carries this counter:
    true_counter = (truth.release_index + settings.sim_seed) & 0xFFFF
    samples = recording.samples
    detected = samples["counter"][
        np.searchsorted(samples["t"], release["data"]["first_free_sample_t_s"] - 1e-9)
    ]
    assert samples.size > 500 and abs(int(detected) - true_counter) <= 1
    (again,) = replay_recording(outcome.path, speed=None)
    assert abs(again.release_t - outcome.release_t) < 0.011
    assert again.fit is not None and again.fit.r2_angle > 0.99


@pytest.mark.slow
def test_a_live_model_with_coulomb_friction_records_fits_and_views_it(tmp_path: Path) -> None:
    """``record --model b1,c1,fc --viewer save`` (once a KeyError 'fc' in the view): every /fit message
    carries fc with its interval, the channel says its unit, and the .rrd plots /coefficients/fc."""
    from rerun.chunk import RrdReader

    from tankdaq.physics.terms import TERM_TABLE

    args = record_args("sim", tmp_path, "--model", "b1,c1,fc", "--viewer", "save", "--runs", "1")
    result = CliRunner().invoke(app, [*args, "--sim-speed", "20", "--sim-seed", "4"])
    assert result.exit_code == 0, result.output
    (path,) = tmp_path.glob("*.mcap")
    with path.open("rb") as f:
        messages = make_reader(f).iter_messages(topics=["/fit"])
        fits = [(channel, json.loads(message.data)) for _, channel, message in messages]
    assert len(fits) >= 2  # the refits and the final fit
    channel = fits[0][0]
    assert json.loads(channel.metadata["term_units"])["fc"] == TERM_TABLE["fc"].unit
    for _, fit in fits:
        assert fit["terms"] == ["b1", "c1", "fc"]
        low, high = fit["ci95"]["fc"]
        assert np.isfinite(fit["coefficients"]["fc"]) and low <= fit["coefficients"]["fc"] <= high
    assert "fit_fc" in read_recording(path).metadata
    fc_values = [
        value
        for chunk in RrdReader(str(path.with_suffix(".rrd"))).stream().to_chunks()
        if chunk.entity_path == "/coefficients/fc" and not chunk.is_static
        for value in chunk.to_record_batch().column("Scalars:scalars").to_pylist()
    ]
    assert fc_values and all(np.isfinite(value).all() for value in fc_values)  # value, 95 % low, high

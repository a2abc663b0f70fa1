"""The web app (agents.tools.serve) as people use it: a real headless Chromium plays both roles by keyboard.

Set ``COOP_GYM_SCREENSHOTS=1`` to write the docs' screenshots (docs/img/web_*.png) from the browser.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from agents.tools import evaluate_cli
from agents.tools.play_log import read_played, score_played
from estimator import estimate

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
HAVE_CHROMIUM = CHROMIUM.exists() and CHROMEDRIVER.exists()
SHOTS = ROOT / "docs" / "img" if os.environ.get("COOP_GYM_SCREENSHOTS") else None

pytestmark = pytest.mark.browser
needs_chromium = pytest.mark.skipif(
    not HAVE_CHROMIUM, reason="no /usr/bin/chromium + /usr/bin/chromedriver (apt-get install chromium chromium-driver)"
)


class Server:
    """``python -m agents.tools.serve`` on a free loopback port, as a subprocess."""

    def __init__(self, database: str, person_trials: int = 1) -> None:
        cmd = [sys.executable, "-m", "agents.tools.serve", "--port", "0", "--database", database,
               "--person-trials", str(person_trials)]  # fmt: skip
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        timer = threading.Timer(120, self.proc.kill)  # a server that never prints its address fails the test
        timer.start()
        line = self.proc.stdout.readline() if self.proc.stdout else ""
        timer.cancel()
        assert line.startswith("coop_gym web app: http://127.0.0.1:"), line
        self.url = line.split()[3].rstrip("/")

    def post(self, path: str, body: Any, headers: dict[str, str] | None = None) -> tuple[int, dict[str, Any]]:
        data = body if isinstance(body, bytes) else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, headers={"Content-Type": "application/json",
                                                                         **(headers or {})})  # fmt: skip
        try:
            with urllib.request.urlopen(req, timeout=60) as response:
                return response.status, json.loads(response.read())
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read() or b"{}")

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=30)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=30)


@pytest.fixture
def database(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'study.sqlite'}"


@pytest.fixture
def server(database: str) -> Iterator[Server]:
    srv = Server(database)
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if not HAVE_CHROMIUM:
        pytest.skip("no /usr/bin/chromium + /usr/bin/chromedriver (apt-get install chromium chromium-driver)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1000,900"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    driver.set_script_timeout(30)
    yield driver
    driver.quit()


def _wait_for(driver: Any, element_id: str, text: str, timeout_s: float = 60.0) -> str:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(driver, timeout_s).until(expected_conditions.text_to_be_present_in_element((By.ID, element_id), text))
    return str(driver.find_element(By.ID, element_id).text)


def _keys(driver: Any, *keys: str, pause_s: float = 0.3) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    for key in keys:
        ActionChains(driver).send_keys(key).perform()
        time.sleep(pause_s)


def _shot(driver: Any, name: str) -> None:
    if SHOTS is not None:
        driver.save_screenshot(str(SHOTS / name))


def _export(database: str, folder: Path) -> None:
    cmd = [sys.executable, "-m", "agents.tools.serve", "--database", database, "--export", str(folder)]
    subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True, text=True, timeout=120)


@needs_chromium
def test_a_caregiver_episode_by_keyboard_is_stored_and_scored_as_its_replay(
    server: Server, browser: Any, database: str, tmp_path: Path
) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    browser.get(server.url + "/")
    browser.find_element(By.ID, "role-caregiver").click()
    _keys(browser, Keys.ENTER, "2", "f", pause_s=0.6)
    _shot(browser, "web_caregiver.png")
    _keys(browser, "l")
    outcome = _wait_for(browser, "outcome", "Stored")
    assert "persona" in outcome and "oracle" in outcome and "prober" in outcome and "belief" in outcome
    with sqlite3.connect(database.removeprefix("sqlite:///")) as db:
        assert db.execute("SELECT COUNT(*) FROM caregiver_trials").fetchone() == (1,)
    _export(database, tmp_path / "out")
    played = read_played(tmp_path / "out" / "caregiver.csv")
    assert len(played) == 1 and played[0].seed == 0 and played[0].actions[-1][2] == 1
    # agents.evaluate --human replays the actions through the evaluation; its record is the played one.
    record = score_played(tmp_path / "out" / "caregiver.csv", played[0].env_id).records[0]
    assert (record.outcome, record.steps) == (played[0].outcome, played[0].steps)
    assert record.episode_return == pytest.approx(played[0].episode_return, abs=1e-9)
    assert played[0].outcome in outcome
    assert evaluate_cli.main(["--human", str(tmp_path / "out" / "caregiver.csv")]) == 0


@needs_chromium
def test_a_person_trial_by_keyboard_is_stored_and_read_by_the_estimator(
    server: Server, browser: Any, database: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    browser.get(server.url + "/")
    browser.execute_script("localStorage.clear()")
    browser.find_element(By.ID, "role-person").click()
    _keys(browser, Keys.ENTER)
    assert "please be" in _wait_for(browser, "request", "please be")
    # A second tab on the same session's running trial is refused.
    first = browser.current_window_handle
    browser.switch_to.new_window("tab")
    browser.get(server.url + "/")
    browser.find_element(By.ID, "role-person").click()
    _keys(browser, Keys.ENTER)
    assert "another tab" in _wait_for(browser, "error", "another tab", 10)
    browser.close()
    browser.switch_to.window(first)
    ActionChains(browser).key_down("f").perform()  # the player intends to lean forward, and holds it
    time.sleep(2.5)
    _shot(browser, "web_person.png")
    ActionChains(browser).key_up("f").perform()
    status = _wait_for(browser, "status", "complete", 90)
    assert "balanced accuracy" in status
    assert "Table I" in browser.find_element(By.ID, "results").text
    with sqlite3.connect(database.removeprefix("sqlite:///")) as db:
        assert db.execute("SELECT COUNT(*) FROM person_trials").fetchone() == (1,)
    _export(database, tmp_path / "out")
    capsys.readouterr()
    assert estimate.main([str(tmp_path / "out" / "person"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_labelled"] == 1 and 0.0 <= summary["balanced_accuracy"] <= 1.0
    assert sum(map(sum, summary["confusion"])) == 1


def _play_person_steps(server: Server, trial: dict[str, Any], steps: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k in range(1, steps + 1):
        body = {"trial_id": trial["trial_id"], "token": trial["token"], "seq": k, "intention_m": 0.1}
        status, out = server.post("/api/person/step", body)
        assert status == 200, out
        if out["scene"]["done"]:
            break
    return out


def test_a_killed_server_keeps_every_finished_trial_and_no_partial_one(database: str) -> None:
    first = Server(database, person_trials=2)
    try:
        _, trial = first.post("/api/person/start", {})
        assert _play_person_steps(first, trial, 200)["stored"]
        _, second = first.post("/api/person/start", {"session_id": trial["session_id"]})
        assert second["trial_index"] == 1
        _play_person_steps(first, second, 30)  # mid-trial ...
        _, episode = first.post("/api/caregiver/start", {})
        body = {"trial_id": episode["trial_id"], "token": episode["token"], "seq": 1, "push": 1, "verbal": 2, "lift": 0}
        assert first.post("/api/caregiver/step", body)[0] == 200
    finally:
        first.kill()  # ... the server dies
    with sqlite3.connect(database.removeprefix("sqlite:///")) as db:
        assert db.execute("PRAGMA journal_mode").fetchone() == ("wal",)
        assert db.execute("SELECT session_id, trial_index FROM person_trials").fetchall() == [(1, 0)]
        assert db.execute("SELECT COUNT(*) FROM caregiver_trials").fetchone() == (0,)
    again = Server(database, person_trials=2)
    try:
        # The restarted server continues the session where its stored trials end.
        status, resumed = again.post("/api/person/start", {"session_id": trial["session_id"]})
        assert status == 200 and resumed["trial_index"] == 1
        done = _play_person_steps(again, resumed, 200)
        assert done["results"]["n_labelled"] == 2
        assert again.post("/api/caregiver/start", {})[1]["scene"]["seed"] == 0
    finally:
        again.stop()


def test_hostile_requests_are_refused_with_a_clear_error(server: Server) -> None:
    _, trial = server.post("/api/caregiver/start", {})
    good = {"trial_id": trial["trial_id"], "token": trial["token"], "seq": 1, "push": 0, "verbal": 0, "lift": 0}
    cases = [
        (b"{not json", 400, "malformed JSON"),
        (b"[1, 2]", 400, "expected a JSON object"),
        ({**good, "push": 3}, 400, "push must be an integer in 0..2"),
        ({**good, "lift": "yes"}, 400, "lift must be an integer"),
        ({**good, "token": "stolen"}, 409, "another tab"),
        ({**good, "seq": 5}, 409, "out of order"),
        ({**good, "trial_id": "nope"}, 404, "no running CaregiverTrial"),
    ]
    for body, status, message in cases:
        got, out = server.post("/api/caregiver/step", body)
        assert (got, message in out.get("error", "")) == (status, True), (body, got, out)
    assert server.post("/api/caregiver/step", good)[0] == 200
    assert server.post("/api/caregiver/step", good)[0] == 409  # the same step sent twice
    got, out = server.post("/api/attach", {"trial_id": trial["trial_id"]})
    assert got == 409 and "another tab" in out["error"]
    got, out = server.post("/api/caregiver/start", {}, headers={"Origin": "http://evil.example"})
    assert got == 403 and "cross-origin" in out["error"]
    _, person = server.post("/api/person/start", {})
    body = {"trial_id": person["trial_id"], "token": person["token"], "seq": 1}
    for bad in (float("nan"), 1.0, "0.1", None):
        got, out = server.post("/api/person/step", {**body, "intention_m": bad})
        assert got == 400 and "intention_m must be a number in" in out["error"]
    req = urllib.request.Request(server.url + "/", headers={"Host": "evil.example"})
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(req, timeout=30)
    assert err.value.code == 400

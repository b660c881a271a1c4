"""The virtual-time event loop: its time jumps only when every party waits — never while a
socket has data for it, an executor job or a subprocess it started is still working.

Real loopback sockets, real threads and real subprocesses; nothing is timed on the wall clock
(the assertions are on the loop's virtual time, which no load can move).
"""

from __future__ import annotations

import asyncio
import sys
import threading
from datetime import UTC, datetime, timedelta

import pytest

from impctl.clock import VirtualClock
from impctl.clock import loop as vtime
from impctl.daemon.nights.schedule import sleep_until

EPOCH = datetime(2026, 1, 12, 12, 0, tzinfo=UTC)


def test_sleeps_jump_to_the_next_timer_in_order():
    async def main():
        loop = asyncio.get_running_loop()
        t0, seen = loop.time(), []

        async def sleeper(delay_s: float) -> None:
            await asyncio.sleep(delay_s)
            seen.append((delay_s, loop.time() - t0))

        await asyncio.gather(*(sleeper(d) for d in (3600.0, 0.25, 86400.0, 7.0)))
        return seen, loop.jumps

    seen, jumps = vtime.run(main())
    # Each woke exactly at its own time, in time order; one jump per distinct timer.
    assert seen == [(0.25, 0.25), (7.0, 7.0), (3600.0, 3600.0), (86400.0, 86400.0)]
    assert jumps == 4


def test_timeouts_fire_on_virtual_time():
    async def main():
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(asyncio.Event().wait(), timeout=600.0)
        return loop.time() - t0

    assert vtime.run(main()) == 600.0


def test_the_clock_waits_for_loopback_tcp():
    """A request/answer over a real loopback socket, both ends on the loop, takes no virtual
    time, even with a short timeout and a timer due meanwhile."""
    async def main():
        loop = asyncio.get_running_loop()

        async def echo(reader, writer):
            while data := await reader.read(100):
                writer.write(data[::-1])
                await writer.drain()
            writer.close()

        server = await asyncio.start_server(echo, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        ticks: list[float] = []

        async def ticker():  # a timer always due soon, as the simulator's model steps
            while True:
                await asyncio.sleep(0.01)
                ticks.append(loop.time())

        tick_task = asyncio.create_task(ticker())
        t0 = loop.time()
        answers = []
        for i in range(300):
            writer.write(f"q{i:03d}".encode())
            answers.append(await asyncio.wait_for(reader.readexactly(4), timeout=0.005))
        spent = loop.time() - t0
        tick_task.cancel()
        writer.close()
        server.close()
        await server.wait_closed()
        return answers, spent, ticks

    answers, spent, ticks = vtime.run(main())
    assert answers == [f"q{i:03d}".encode()[::-1] for i in range(300)]
    assert spent == 0.0 and ticks == []


def test_the_clock_stands_still_while_an_executor_job_runs():
    """A thread that takes real time (here: until the loop's other timers had every chance to
    fire) takes no virtual time; the timers fire after it, at their own virtual times."""
    release = threading.Event()

    def job() -> str:
        release.wait(5.0)  # a guard: released below long before
        return "done"

    async def main():
        loop = asyncio.get_running_loop()
        t0, fired = loop.time(), []
        loop.call_later(0.5, lambda: fired.append(loop.time() - t0))
        future = loop.run_in_executor(None, job)
        # Let the loop spin for a while of real time while the job runs.
        threading.Timer(0.3, release.set).start()
        result = await asyncio.wait_for(future, timeout=1.0)
        at_result = loop.time() - t0
        await asyncio.sleep(1.0)
        return result, at_result, fired, loop.held_s

    result, at_result, fired, held_s = vtime.run(main())
    assert (result, at_result, fired) == ("done", 0.0, [0.5])
    assert held_s > 0  # it did wait in real time


def test_to_thread_is_held_too():
    async def main():
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        out = await asyncio.wait_for(asyncio.to_thread(sum, range(10 ** 6)), timeout=1e-6)
        return out, loop.time() - t0

    assert vtime.run(main()) == (sum(range(10 ** 6)), 0.0)


def _child(seconds: float) -> list[str]:
    return [sys.executable, "-c", f"import time; time.sleep({seconds}); print('ok')"]


def test_a_subprocess_takes_no_virtual_time():
    """A fit in a subprocess is instantaneous in simulated time: a timeout far shorter than
    the process's real run time does not fire, and no timer runs before it has exited."""
    async def main():
        loop = asyncio.get_running_loop()
        t0, fired = loop.time(), []
        loop.call_later(0.001, lambda: fired.append(loop.time() - t0))
        proc = await asyncio.create_subprocess_exec(*_child(0.3),
                                                    stdout=asyncio.subprocess.PIPE)
        out, _ = await asyncio.wait_for(proc.communicate(), timeout=0.01)
        return out, loop.time() - t0, list(fired)

    out, spent, fired = vtime.run(main())
    assert (out, spent, fired) == (b"ok\n", 0.0, [])


def test_without_waiting_for_processes_the_clock_runs_on():
    async def main():
        proc = await asyncio.create_subprocess_exec(*_child(30))
        try:
            await asyncio.wait_for(proc.wait(), timeout=3600.0)
        except TimeoutError:
            return "timed out"
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
        return "exited"

    assert vtime.run(main(), wait_for_processes=False) == "timed out"


def test_a_clock_on_the_loop_follows_its_time():
    async def main():
        clock = VirtualClock.on_loop(EPOCH, 3600.0)
        start = clock.now()
        await asyncio.sleep(2.0)
        return start, clock.now(), clock

    start, later, clock = vtime.run(main())
    assert start == EPOCH and later == EPOCH + timedelta(hours=2)
    assert "event loop's time" in repr(clock)
    with pytest.raises(ValueError, match="cannot be shared"):
        clock.spec()


def test_sleep_until_wakes_on_time_on_a_loop_clock():
    """The daemon's sleeps to instants on a loop clock end on time — never early, late by at
    most its shortest sleep (1 µs of the loop's time; float rounding of the clock never makes
    them spin) — at any speed."""
    async def main(speed: float):
        clock = VirtualClock.on_loop(EPOCH, speed)
        lates = []
        for k in range(1, 200):
            when = EPOCH + timedelta(seconds=k * 997.123456)
            lates.append(await sleep_until(clock, when))
        return lates

    for speed in (1.0, 600.0, 20000.0, 43200.0):
        lates = vtime.run(main(speed))
        assert all(0 <= late <= 1e-6 * speed + 1e-6 for late in lates), (
            speed, min(lates), max(lates))


def test_the_same_run_twice_is_the_same_trace():
    """Timers, tasks, loopback I/O and executor jobs interleaved: the virtual times at which
    things happen are the same on every run."""
    async def main():
        loop = asyncio.get_running_loop()
        t0, trace = loop.time(), []

        async def serve(reader, writer):
            while data := await reader.read(64):
                await asyncio.sleep(0.003)  # a device that answers after a pause
                writer.write(data)

        server = await asyncio.start_server(serve, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]

        async def client(name: str, period_s: float):
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            for i in range(40):
                writer.write(f"{name}{i}".encode())
                await reader.read(64)
                total = await asyncio.to_thread(sum, range(1000 * i))
                trace.append((name, i, total, round(loop.time() - t0, 9)))
                await asyncio.sleep(period_s)
            writer.close()

        await asyncio.gather(client("a", 0.07), client("b", 0.11), client("c", 0.013))
        server.close()
        await server.wait_closed()
        return trace

    first, second = vtime.run(main()), vtime.run(main())
    assert first == second and len(first) == 120

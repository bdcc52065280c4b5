# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""A harness for tests and benchmarks: the emulator run as a child process."""

import queue
import subprocess
import sys
import threading


class EmulatorProcess:
    """
    ``rplidar_emulator`` in a child process, controlled through its standard input.

    :param args: command line arguments, e.g. ``['--noiseless', '--tcp-port', '0']``
    :param startup_timeout_s: longest wait for the emulator to be ready, s
    :param module: the emulator's module (the lab's ``wctls_lab.simulated_rplidar`` sees a
        floor plan)
    :ivar pty: the pseudo-terminal's device path
    :ivar link: the symlink to it (None without ``--link``)
    :ivar tcp_port: the TCP port served (None without ``--tcp-port``)
    :raises RuntimeError: when it does not become ready
    """

    def __init__(self, args: list = (), startup_timeout_s: float = 20.0,
                 module: str = 'wctls_rplidar.emulator.cli'):
        self._process = subprocess.Popen(
            [sys.executable, '-m', module, *args], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True, bufsize=1)
        self._lines = queue.Queue()
        threading.Thread(target=self._forward_lines, daemon=True).start()
        self.link = self.tcp_port = None
        while True:
            line = self._next_line(startup_timeout_s)
            key, _, value = line.partition(' ')
            if key == 'pty':
                self.pty = value
            elif key == 'link':
                self.link = value
            elif key == 'tcp':
                self.tcp_port = int(value.rsplit(':', 1)[1])
            elif key == 'ready:':
                break

    def _forward_lines(self):
        for line in self._process.stdout:
            self._lines.put(line.strip())
        self._lines.put(None)

    def _next_line(self, timeout_s: float) -> str:
        try:
            line = self._lines.get(timeout=timeout_s)
        except queue.Empty:
            line = None
        if line is None:
            self.close()
            raise RuntimeError('rplidar_emulator did not answer (see its standard error)')
        return line

    def command(self, line: str, timeout_s: float = 5.0) -> str:
        """
        Send a control command and return its acknowledgement.

        :param line: e.g. ``'unplug'``, ``'health error 2'``
        :param timeout_s: longest wait for the acknowledgement, s
        :return: the acknowledgement line
        :raises RuntimeError: when the emulator does not answer
        """
        self._process.stdin.write(line + '\n')
        self._process.stdin.flush()
        return self._next_line(timeout_s)

    def close(self):
        """Stop the emulator (quit, then kill if needed)."""
        if self._process.poll() is None:
            try:
                self._process.stdin.write('quit\n')
                self._process.stdin.flush()
                self._process.wait(5.0)
            except (OSError, subprocess.TimeoutExpired):
                self._process.kill()
                self._process.wait()
        self._process.stdin.close()
        self._process.stdout.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()

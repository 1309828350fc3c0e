"""keep_freed_buffers: a frame's megabyte buffers stop page-faulting once set; the environment's
own malloc settings are left alone."""
import os
import platform
import subprocess
import sys
import textwrap

import pytest

from colorglove_ros.ros.heap_tuning import keep_freed_buffers

# a frame's buffers as segmentation_node makes them (a taken image, its Python bytes, a copy),
# allocated and freed 100 times; prints the minor page faults per round
_FRAMES = textwrap.dedent('''
    import resource, sys
    from colorglove_ros.ros.heap_tuning import keep_freed_buffers
    if sys.argv[1] == 'tuned':
        assert keep_freed_buffers().applied
    def frame():
        taken = bytearray(921600)
        data = bytes(taken)
        return len(bytearray(data))
    for _ in range(5):
        frame()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(100):
        frame()
    print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 100)
''')


def _faults_per_frame(mode: str) -> float:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith('MALLOC_') and k != 'GLIBC_TUNABLES'}
    done = subprocess.run([sys.executable, '-c', _FRAMES, mode], capture_output=True,
                          text=True, env=env, check=True)
    return float(done.stdout.strip())


@pytest.mark.skipif(platform.libc_ver()[0] != 'glibc', reason='glibc malloc only')
def test_freed_frame_buffers_no_longer_page_fault():
    untuned, tuned = _faults_per_frame('default'), _faults_per_frame('tuned')
    # by default each round faults in most of the buffers' 2.7 MB afresh (4 KiB pages)
    assert untuned > 300
    assert tuned < 10


@pytest.mark.parametrize('environ', [{'MALLOC_MMAP_THRESHOLD_': '65536'},
                                     {'MALLOC_TRIM_THRESHOLD_': '0'},
                                     {'GLIBC_TUNABLES': 'glibc.malloc.trim_threshold=1'}])
def test_the_environments_own_malloc_settings_are_kept(environ):
    done = keep_freed_buffers(environ)
    assert not done.applied
    assert 'left to the environment' in done.note


@pytest.mark.skipif(platform.libc_ver()[0] != 'glibc', reason='glibc malloc only')
def test_applied_on_glibc_says_so():
    done = keep_freed_buffers({'GLIBC_TUNABLES': 'glibc.rtld.nns=2'})
    assert done.applied
    assert 'MiB' in done.note


def test_every_node_process_keeps_freed_buffers(monkeypatch):
    from colorglove_ros.ros.heap_tuning import HeapTuning
    from colorglove_ros.ros.nodes import common

    calls = []
    monkeypatch.setattr(common, 'keep_freed_buffers',
                        lambda: calls.append(1) or HeapTuning(False, 'test'))

    def refuse():
        raise common.StartupError('no start in this test')
    assert common.run_node(refuse, []) == 1
    assert calls == [1]

"""A gate for the interrupt tests, loaded by every Python process started with this folder on
PYTHONPATH (the splatgl process and the worker processes it spawns): once a process has
written ``$SPLATGL_TEST_GATE`` frames, its render loop prints ``gate <pid>`` on stdout and waits
until a signal ends it.  The test reads those lines, then signals: the signal always lands in
the middle of the run, with a known set of frames written, whatever the load on the machine.
"""

import os

if os.environ.get("SPLATGL_TEST_GATE"):
    import threading

    from splatgl.imagefiles import images as image_io
    from splatgl.api import Renderer

    _after = int(os.environ["SPLATGL_TEST_GATE"])
    _written = threading.Condition()
    _count = [0]
    _write, _render_many = image_io.write_image, Renderer.render_many

    def write_image(*args, **kwargs):
        _write(*args, **kwargs)
        with _written:
            _count[0] += 1
            _written.notify_all()

    def render_many(self, *args, **kwargs):
        for n, frame in enumerate(_render_many(self, *args, **kwargs)):
            if n == _after:
                with _written:  # the frames handed to the writer thread are on disk
                    _written.wait_for(lambda: _count[0] >= _after)
                print("gate", os.getpid(), flush=True)
                threading.Event().wait()  # until SIGINT / SIGTERM raises here
            yield frame

    image_io.write_image = write_image  # before splatgl.tasks.batch imports it
    Renderer.render_many = render_many

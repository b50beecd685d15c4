"""moto's S3 (and IAM) server on 127.0.0.1:PORT for the tests and `bench convert`, which exits
on its own once the process that started it is gone (a test binary that shares one server
between its tests never drops it)."""
import os
import sys
import threading
import time


def watch(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(0)


threading.Thread(target=watch, args=(os.getppid(),), daemon=True).start()
from moto.server import main  # noqa: E402

main(["-H", "127.0.0.1", "-p", sys.argv[1]])

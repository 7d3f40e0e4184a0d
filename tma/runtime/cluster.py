"""Shards on a Dask cluster (``parallel=dask``): a client of a scheduler's address, checked
before it is trusted (``address_problem``, ``check_scheduler``: one line for a malformed,
refused, unknown or foreign address), or of a LocalCluster started once per process
(``dask_client``); closed at exit."""

import atexit
import functools
import logging
import socket
import time
from concurrent.futures import ThreadPoolExecutor
from urllib.parse import urlsplit

from tma.errors import ConfigError

log = logging.getLogger(__name__)
SCHEMES = ("tcp", "tls", "ws", "wss")  # the transports of a Dask scheduler's address
CONNECT_TIMEOUT = 10.0  # s: parallel.connect_timeout's default
ADDRESS_FORM = "a scheduler address looks like tcp://scheduler:8786"


def address_problem(address) -> str:
    """What is wrong with a Dask scheduler address as written ('' if nothing): its scheme,
    host and port, checked before any connection."""
    if not isinstance(address, str) or "://" not in address:
        return "not a scheduler address"
    scheme, _, rest = address.partition("://")
    if scheme not in SCHEMES:
        return f"unknown scheme '{scheme}://' (Dask's are {', '.join(f'{s}://' for s in SCHEMES)})"
    try:
        parts = urlsplit(address)
    except ValueError as exc:  # e.g. an unclosed [ of an IPv6 host
        return f"not a scheduler address ({exc})"
    if parts.path or parts.query or parts.fragment or parts.username is not None:
        return f"unexpected text around host:port in '{rest}'"
    if not parts.hostname:
        return "no host"
    port = parts.netloc.rpartition("]")[2].rpartition(":")[2] if ":" in parts.netloc else ""
    if not port:
        return "no port (a Dask scheduler listens on 8786 unless told otherwise)"
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        return f"port '{port}' is not a number from 1 to 65535"
    return ""


async def _dask_identity(address: str, connection_args: dict) -> dict:
    from distributed.comm import connect

    # connect() bounds the TCP connection by its timeout, but then waits for the other end's
    # handshake with no bound at all: the caller bounds the whole exchange
    comm = await connect(address, **connection_args)
    try:
        await comm.write({"op": "identity"})
        return await comm.read()
    finally:
        comm.abort()


def _tcp_reachable(address: str, timeout: float) -> None:
    """Return once something at ``address`` accepts a TCP connection; retried (a scheduler
    may be starting) until ``timeout`` s, then a ConfigError with the last reason."""
    parts = urlsplit(address)
    host, port = parts.hostname, parts.port
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        try:
            socket.create_connection((host, port), timeout=max(left, 0.01)).close()
            return
        except socket.gaierror as exc:
            reason = f"host '{host}' not found ({exc.strerror})"
        except ConnectionRefusedError:
            reason = f"nothing listens on port {port} of {host} (connection refused)"
        except TimeoutError:
            reason = f"{host}:{port} accepts no connection"
        except OSError as exc:
            reason = f"cannot connect to {host}:{port} ({exc.strerror or exc})"
        if time.monotonic() + 0.1 > deadline:
            raise ConfigError(f"parallel.address={address}: {reason} after "
                              f"{timeout:g} s (parallel.connect_timeout)")
        time.sleep(0.1)


def check_scheduler(address: str, timeout: float, connection_args: dict) -> None:
    """Make sure a Dask scheduler answers at ``address``: a ConfigError naming the address and
    what is wrong, within about twice ``timeout`` s, whatever listens there.

    ``distributed.Client(address, timeout=...)`` alone would wait forever for a service that
    accepts the connection and never speaks Dask's protocol (its handshake read is unbounded);
    an HTTP server reads Dask's first frame as a request line and waits for its end."""
    import asyncio  # 0.05 s: only where a scheduler is probed, not in every command's start-up

    _tcp_reachable(address, timeout)
    probe = asyncio.wait_for(_dask_identity(address, connection_args), timeout)
    try:
        with ThreadPoolExecutor(1) as thread:  # its own event loop, whatever runs in this one
            reply = thread.submit(asyncio.run, probe).result()
    except TimeoutError:
        reason = (f"something there accepts connections but sends no Dask handshake within "
                  f"{timeout:g} s: not a Dask scheduler (or one too busy to answer: "
                  f"parallel.connect_timeout)")
    except OSError:  # CommClosedError among them
        reason = ("something there accepts connections but closes them without a Dask "
                  "handshake: not a Dask scheduler")
    except Exception:  # bytes that are no Dask message (e.g. an absurd frame length)
        reason = "something there answers, but not in Dask's protocol: not a Dask scheduler"
    else:
        kind = reply.get("type") if isinstance(reply, dict) else None
        if kind == "Scheduler" or isinstance(reply, dict) and "n_workers" in reply:
            return
        reason = (f"that is a Dask {kind.lower()}, not the scheduler" if kind in {"Worker", "Nanny"}
                  else f"it speaks Dask's protocol but is not a scheduler ({kind or reply!r})")
    raise ConfigError(f"parallel.address={address}: {reason}")


def close_dask_clients():
    """Close the clients (and local clusters) ``dask_client`` started."""
    for client in _clients:
        client.close()
        if client.cluster is not None:
            client.cluster.close()
    _clients.clear()
    _dask_client.cache_clear()


_clients = []


def dask_client(address: str | None = None, n_workers: int = 2, *,
                connect_timeout: float = CONNECT_TIMEOUT, verbose: bool = False):
    """A client of the scheduler at ``address``, or of a LocalCluster of ``n_workers``
    single-threaded worker processes started once per process (closed at exit); a scheduler
    that does not answer in ``connect_timeout`` s, or a service that is not one, is a
    ConfigError. ``verbose``: Dask's own INFO logging (else its warnings only)."""
    try:
        import distributed  # noqa: F401 (sets the level of its logger when first imported)
    except ImportError:
        raise ConfigError("parallel=dask needs Dask: pip install 'tma[dask]'") from None
    # distributed sets its logger to INFO and, under Hydra (the root logger has handlers),
    # adds no handler of its own: every record reaches Hydra's console and log file, and
    # LocalCluster's silence_logs, which sets the level of that missing handler, has no effect
    logging.getLogger("distributed").setLevel(logging.INFO if verbose else logging.WARNING)
    return _dask_client(address, n_workers, float(connect_timeout), bool(verbose))


@functools.cache
def _dask_client(address: str | None, n_workers: int, connect_timeout: float, verbose: bool):
    from distributed import Client, LocalCluster
    from distributed.security import Security

    if address is None:
        # silence_logs (a level) goes to every worker process: a worker that closes while its
        # heartbeat to the scheduler is in flight logs that CommClosedError with its traceback
        # at ERROR (a race in distributed's Worker.close); task errors reach the client anyway.
        # The scheduler's HTTP server on a free port of 127.0.0.1, not 8787: a second cluster
        # on this machine would print "Port 8787 is already in use"
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                               dashboard_address=None,
                               scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                               silence_logs=False if verbose else logging.CRITICAL)
        client = Client(cluster)
    else:
        problem = address_problem(address)
        if problem:
            raise ConfigError(f"parallel.address={address}: {problem}; {ADDRESS_FORM}")
        connection_args = Security().get_connection_args("client")
        if address.startswith(("tls://", "wss://")) and connection_args["ssl_context"] is None:
            raise ConfigError(f"parallel.address={address}: TLS needs Dask's TLS settings "
                              f"(distributed.comm.tls.ca-file, .client.cert, .client.key in "
                              f"Dask's configuration)")
        check_scheduler(address, connect_timeout, connection_args)
        try:
            client = Client(address, timeout=connect_timeout)
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"parallel.address={address}: the Dask scheduler stopped "
                              f"answering ({exc})") from None
    if not _clients:
        atexit.register(close_dask_clients)
    _clients.append(client)
    log.info("dask: %s", client)
    return client

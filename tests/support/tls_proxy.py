#!/usr/bin/env python3
"""A TLS-terminating reverse proxy for the PACS tests: HTTPS on 127.0.0.1 (a free port, printed
on the first line of stdout) in front of an HTTP server on 127.0.0.1:BACKEND_PORT, the way
Orthanc's own documentation advises serving it over HTTPS. Python's standard library only.

    tls_proxy.py CERT_PEM KEY_PEM BACKEND_PORT

Runs until killed; one thread pair per connection copies bytes both ways."""
import socket
import ssl
import sys
import threading


def pump(src, dst):
    try:
        while True:
            data = src.recv(65536)
            if not data:
                break
            dst.sendall(data)
    except OSError:
        pass
    finally:
        for s in (src, dst):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


def serve(conn, backend_port):
    try:
        upstream = socket.create_connection(("127.0.0.1", backend_port))
    except OSError:
        conn.close()
        return
    threading.Thread(target=pump, args=(conn, upstream), daemon=True).start()
    pump(upstream, conn)


def main():
    cert, key, backend_port = sys.argv[1], sys.argv[2], int(sys.argv[3])
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(cert, key)
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind(("127.0.0.1", 0))
    listener.listen(16)
    print(listener.getsockname()[1], flush=True)
    while True:
        raw, _ = listener.accept()
        try:
            conn = context.wrap_socket(raw, server_side=True)
        except (ssl.SSLError, OSError):
            raw.close()  # a client that refuses our certificate ends its handshake here
            continue
        threading.Thread(target=serve, args=(conn, backend_port), daemon=True).start()


if __name__ == "__main__":
    main()

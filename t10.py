import socket, sys, time, resource
port = int(sys.argv[1]); n = int(sys.argv[2])
socks = []
for i in range(n):
    socks.append(socket.create_connection(("127.0.0.1", port), timeout=2))
print("opened", len(socks)); sys.stdout.flush()
time.sleep(int(sys.argv[3]))
# can a new real client get in?
s = socket.create_connection(("127.0.0.1", port), timeout=2)
s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
try: print("page:", s.recv(100)[:40])
except Exception as e: print("page error", e)

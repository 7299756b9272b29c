# The quick start's JSON client: a Command from vehicle 1 to vehicle 2, its
# reception on vehicle 2 and its ack on vehicle 1. Run it once both daemons
# are up (gobyd -c gobyd/config/vehicle1.pb.txt, and vehicle2.pb.txt).
import json
import socket

v1 = socket.create_connection(("127.0.0.1", 11141), timeout=300)
v2 = socket.create_connection(("127.0.0.1", 11142), timeout=300)
v1_lines, v2_lines = v1.makefile(), v2.makefile()  # one JSON object a line

v1.sendall(b'{"subscribe": ["ack"]}\n')
print(v1_lines.readline(), end="")  # {"subscribed":["ack"],"reply":1}
command = {"destination": 2, "action": "GOTO",
           "waypoint": [{"x": 120, "y": -40}], "note": "survey A"}
v1.sendall(json.dumps({"publish": "goby.example.Command", "msg": command}).encode() + b"\n")
print(v1_lines.readline(), end="")  # {"accepted":"goby.example.Command","id":...,"reply":2}
print(v2_lines.readline(), end="")  # {"event":"received","received":"goby.example.Command","src":1,"dest":2,...}
print(v1_lines.readline(), end="")  # {"event":"ack","ack":"goby.example.Command",...,"by":2,...}

# A script written for the reference (C++-backed) dccl binding, in the form
# of its quick start: load the .proto, encode a message of the generated
# class, decode it back. It must run unchanged on this package.
# Usage: python quick.py PATH/TO/navigation.proto  (navigation_pb2 importable)
import os
import sys
import time

import dccl
from goby.example import navigation_pb2

dccl.loadProtoFile(os.path.abspath(sys.argv[1]))

codec = dccl.Codec()
codec.load("goby.example.NavigationReport")

# SENDER
r_out = navigation_pb2.NavigationReport(
    source=3, destination=0, time=int(time.time()), x=450, y=550, z=-100,
    veh_class=navigation_pb2.NavigationReport.AUV, battery_ok=True)
encoded_bytes = codec.encode(r_out)

# send encoded_bytes across your link

# RECEIVER
if codec.id(encoded_bytes) == codec.id("goby.example.NavigationReport"):
    decoded_msg = codec.decode(encoded_bytes)
    print(decoded_msg)
    print("size", codec.size(r_out), "type", type(decoded_msg).__module__, "same", decoded_msg == r_out)

#!/usr/bin/env python3
"""GUIDED position setpoints against velocity setpoints on ArduSub SITL (issue 29's question).

Talks to a running SITL as its GCS (system 255) on PORT (SERIAL0, 5760 + 10 x INSTANCE; start
SITL with ../shared/peers/ardusub/run-sitl.sh and nothing else connected): waits for the EKF's
position, ALT_HOLD, arms, GUIDED, then flies four legs of about 3.2 m (3, 1, 1 m and back to
0.5 m depth): position setpoint, velocity setpoint of 0.5 m/s toward the target switched to the
position setpoint within 0.5 m, and both again; prints for each the time to 0.5 m and 0.3 m and
the largest error over the 10 s of hold after.

Usage: python3 scripts/ardusub-guided-speed.py PORT
"""
import os, sys, time, math
os.environ["MAVLINK20"]="1"
from pymavlink import mavutil
port=int(sys.argv[1])
m=mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255, source_component=190)
M=mavutil.mavlink
pos=None; last_hb=0
def pump(t=0.05):
    global pos,last_hb
    end=time.time()+t
    while True:
        if time.time()-last_hb>=1:
            m.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID,0,0,M.MAV_STATE_ACTIVE); last_hb=time.time()
        msg=m.recv_match(blocking=True,timeout=max(0.001,end-time.time()))
        if msg and msg.get_type()=="LOCAL_POSITION_NED": pos=(msg.x,msg.y,msg.z)
        if msg and msg.get_type()=="STATUSTEXT" and msg.severity<=4: print("TEXT",msg.text,flush=True)
        if time.time()>=end: return
t0=time.time()
while pos is None: pump(0.5)
print(f"position after {time.time()-t0:.1f} s", pos, flush=True)
m.mav.command_long_send(1,1,M.MAV_CMD_SET_MESSAGE_INTERVAL,0,32,1e5,0,0,0,0,0)
def mode(n):
    for _ in range(20):
        m.mav.command_long_send(1,1,M.MAV_CMD_DO_SET_MODE,0,1,n,0,0,0,0,0); pump(0.5)
        if m.messages.get("HEARTBEAT") and m.messages["HEARTBEAT"].custom_mode==n: return
    raise SystemExit(f"mode {n} not set")
mode(2)
for _ in range(20):
    m.mav.command_long_send(1,1,M.MAV_CMD_COMPONENT_ARM_DISARM,0,1,0,0,0,0,0,0); pump(0.5)
    hb=m.messages.get("HEARTBEAT")
    if hb and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED: break
print("armed", flush=True)
mode(4)
def pos_sp(t):
    m.mav.set_position_target_local_ned_send(0,1,1,M.MAV_FRAME_LOCAL_NED,0x9F8|0,t[0],t[1],t[2],0,0,0,0,0,0,0.0,0)
# Velocity only: position, acceleration, yaw and yaw rate ignored.
def vel_sp(v):
    m.mav.set_position_target_local_ned_send(0,1,1,M.MAV_FRAME_LOCAL_NED,0b110111000111,0,0,0,v[0],v[1],v[2],0,0,0,0,0)
def dist(a,b): return math.sqrt(sum((a[k]-b[k])**2 for k in range(3)))
def run(name, target, velocity):
    start=time.time(); p0=pos; d0=dist(pos,target); t05=t03=None; last_sp=0; switched=False
    while time.time()-start<90:
        d=dist(pos,target)
        if t05 is None and d<=0.5: t05=time.time()-start
        if t03 is None and d<=0.3: t03=time.time()-start; break
        if velocity and d>0.5:
            e=[target[k]-pos[k] for k in range(3)]; v=[0.5*x/d for x in e]; vel_sp(v)
        elif time.time()-last_sp>=1 or (velocity and not switched):
            pos_sp(target); last_sp=time.time(); switched=True
        pump(0.1)
    # hold 10 s
    hold=0; hs=time.time()
    while time.time()-hs<10:
        if time.time()-last_sp>=1: pos_sp(target); last_sp=time.time()
        pump(0.1); hold=max(hold,dist(pos,target))
    print(f"{name}: {d0:.2f} m, to 0.5 m {t05}, to 0.3 m {t03} s, mean {d0/t03 if t03 else 0:.2f} m/s, hold max {hold:.2f} m over 10 s", flush=True)
A=pos; B=(A[0]+3,A[1]+1,A[2]+1)
pos_sp(A)
run("position A->B", B, False)
run("velocity B->A", (A[0],A[1],A[2]+0.5), True)
run("position A'->B", B, False)
run("velocity B->A'", (A[0],A[1],A[2]+0.5), True)

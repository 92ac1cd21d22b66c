// Writes the seed corpora of the fuzz targets (tests/fuzz/corpus/<target>/): run it once after a
// format changes and commit what it writes. Usage: fuzz_make_seeds CORPUS_DIR
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"
#include "vdyn/control.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/io/vehicle_params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"
#include "vdyn/recorder/mcap.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"

namespace fs = std::filesystem;

namespace {
void Write(const fs::path& dir, const std::string& name, const std::string& bytes) {
  fs::create_directories(dir);
  std::ofstream(dir / name, std::ios::binary) << bytes;
}

std::string ReadAll(const fs::path& p) {
  std::ostringstream bytes;
  bytes << std::ifstream(p, std::ios::binary).rdbuf();
  return bytes.str();
}

// A small recording of a real drive, as the recorder writes one: a ground quad, one vehicle
// spawned and driven for 60 steps by an input that changes every step (input batches every 10
// steps, a checkpoint every 20), every state with its hash - what `vdyn-recorder verify`
// re-simulates bit for bit. Chunks of 16 KiB, with or without CRCs.
void WriteDrive(const fs::path& path, bool chunk_crc) {
  namespace rec = vdyn::recorder;
  using vdyn::transport::TopicId;
  vdyn::TriangleMesh ground;
  ground.name = "ground";
  ground.AddQuad({-60, -60, 0}, {60, -60, 0}, {60, 60, 0}, {-60, 60, 0});
  std::shared_ptr<const vdyn::World> world = vdyn::WorldFromMesh(std::move(ground), vdyn::Pose2{});
  const std::int64_t step_ns = 1'000'000;
  const vdyn::pb::WorldDescription description = vdyn::DescribeWorld(*world, "seed", step_ns);
  const std::uint64_t terrain_hash = vdyn::TerrainHash(world->terrain);
  const vdyn::pb::VehicleParams params = vdyn::DefaultVehicleParams();
  vdyn::SimConfig config;
  config.step_ns = step_ns;
  vdyn::Simulator sim(world, vdyn::ParamsFromProto(params), config);

  vdyn::mcap::WriterOptions options;
  options.chunk_bytes = 16 * 1024;
  vdyn::mcap::Writer w(path, options);
  w.SetChunkCrc(chunk_crc);
  auto channel = [&](TopicId t, std::uint32_t key) {
    const auto* d = rec::PayloadDescriptor(t);
    return w.AddChannel(w.AddSchema(d->full_name(), "protobuf", rec::FileDescriptorSetOf(d)),
                        rec::ChannelTopic(t, key), "protobuf", rec::ChannelMetadata(t, key));
  };
  const std::uint16_t world_ch = channel(TopicId::kWorld, 0x5eed);
  const std::uint16_t events_ch = channel(TopicId::kEvents, 1);
  const std::uint16_t state_ch = channel(TopicId::kState, 1);
  w.WriteMetadata("vdyn.recording", {{"format", rec::kFormatVersion},
                                     {"topics", "vdyn/state,vdyn/events,vdyn/world"}});
  const std::uint64_t t0 = 1'800'000'000'000'000'000ull;
  std::uint32_t sequence_per_channel = 0;
  auto put = [&](std::uint16_t ch, std::uint64_t t, const google::protobuf::Message& m) {
    const std::string b = m.SerializeAsString();
    w.WriteMessage(ch, sequence_per_channel++, t, t,
                   {reinterpret_cast<const std::uint8_t*>(b.data()), b.size()});
  };
  put(world_ch, t0, description);
  std::uint64_t event_sequence = 0;  // numbered as they are sent
  auto event = [&](std::uint64_t step) {
    vdyn::pb::SessionEvent e;
    e.set_vehicle_id(1);
    e.set_server_id("seed");
    e.set_step(step);
    return e;
  };
  auto send = [&](vdyn::pb::SessionEvent& e, std::uint64_t t) {
    e.set_sequence(event_sequence++);
    put(events_ch, t, e);
  };
  {
    vdyn::pb::SessionEvent e = event(0);
    auto* s = e.mutable_spawned();
    *s->mutable_state() = vdyn::ToExactState(sim.state());
    *s->mutable_params() = params;
    s->set_world_name(world->name);
    s->set_terrain_hash(terrain_hash);
    s->set_step_ns(step_ns);
    send(e, t0 + 1);
  }
  vdyn::pb::SessionEvent batch;
  for (std::uint64_t k = 0; k < 60; ++k) {
    const std::uint64_t t = t0 + (k + 1) * 1'000'000;
    vdyn::DriverInput in;
    in.throttle = 0.4 + 0.3 * std::sin(0.05 * static_cast<double>(k));
    in.steer = 0.08 * std::sin(0.03 * static_cast<double>(k));
    sim.SetInput(in);
    if (batch.input_batch().samples_size() == 0) batch = event(k);
    vdyn::ToInputSample(in, static_cast<std::int64_t>(k),
                        *batch.mutable_input_batch()->add_samples());
    if (sim.Step() != vdyn::StepStatus::kOk) std::abort();
    const vdyn::StepRecord& r = sim.last_step();
    vdyn::pb::DriverInput msg;
    msg.set_vehicle_id(1);
    msg.set_source_id("seed-rig");
    vdyn::ToProto(in, msg);
    vdyn::pb::VehicleState state;
    vdyn::FillVehicleState(1, "seed", step_ns, static_cast<std::int64_t>(k) * step_ns, r, msg,
                           false, r.derived.steering_torque, state);
    put(state_ch, t, state);
    const std::uint64_t next = k + 1;
    if (next % 10 == 0) {
      send(batch, t + 100);
      batch.Clear();
    }
    if (next % 20 == 0) {
      vdyn::pb::SessionEvent e = event(next);
      auto* c = e.mutable_checkpoint();
      *c->mutable_state() = vdyn::ToExactState(sim.state());
      *c->mutable_params() = params;
      vdyn::ToInputSample(sim.input(), static_cast<std::int64_t>(next), *c->mutable_input());
      c->set_terrain_hash(terrain_hash);
      c->set_step_ns(step_ns);
      send(e, t + 200);
    }
  }
  w.Close();
}

std::string Tagged(char tag, const std::string& bytes) { return std::string(1, tag) + bytes; }
}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR\n", argv[0]);
    return 2;
  }
  const fs::path root(argv[1]);
  // Maneuvers.
  Write(root / "maneuver", "demo.csv", vdyn::DemoManeuverCsv());
  Write(root / "maneuver", "reordered.csv",
        "# comment\r\nbrake,t_s,throttle,steer_deg\r\n0,0,0.5,1\r\n0.2,1.5,0,-2\r\n");
  Write(root / "maneuver", "cruise.csv", "t_s,steer_deg,throttle,brake,cruise_kmh\n0,0,0,0,36\n10,0,0,0,\n");
  // Vehicle parameters: text (first byte even) and JSON (odd).
  Write(root / "vehicle_params", "defaults.txt", Tagged('\0', vdyn::DumpVehicleParamsText(vdyn::DefaultVehicleParams())));
  Write(root / "vehicle_params", "change.txt", Tagged('\0', "mass: 1600\nlf { spring_stiffness: 32000 }\nmodel: VEHICLE_MODEL_PAPER\n"));
  Write(root / "vehicle_params", "change.json", Tagged('\1', R"({"mass": 1400, "yawMode": "YAW_MODE_PAPER", "rr": {"radius": 0.33}})"));
  // Terrain files (first byte picks the format: 0 obj, 1 stl, 7 pgm, 8 bmp).
  Write(root / "world_file", "quad.obj", Tagged('\0', "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\nf 1 2 3\nf 1 3 4\n"));
  Write(root / "world_file", "tri.stl", Tagged('\1', "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 10 0 0\nvertex 0 10 0\nendloop\nendfacet\nendsolid t\n"));
  Write(root / "world_file", "hm.pgm", Tagged('\7', std::string("P5\n3 2\n255\n") + std::string("\x00\x40\x80\xc0\xff\x10", 6)));
  {
    std::string bmp = "BM";
    auto le = [&bmp](std::uint32_t v, int n) { for (int i = 0; i < n; ++i) bmp += static_cast<char>((v >> (8 * i)) & 0xff); };
    le(54 + 8, 4); le(0, 4); le(54, 4); le(40, 4); le(2, 4); le(2, 4); le(1, 2); le(8, 2);
    le(0, 4); le(8, 4); le(0, 4); le(0, 4); le(0, 4); le(0, 4);
    bmp += std::string("\x10\x20\x00\x00\x30\x40\x00\x00", 8);
    Write(root / "world_file", "hm.bmp", Tagged('\x08', bmp));
  }
  // World descriptions: a small world of two meshes, as a server describes it.
  {
    vdyn::TriangleMesh ground;
    ground.name = "ground";
    ground.AddQuad({-20, -20, 0}, {20, -20, 0}, {20, 20, 0}, {-20, 20, 0});
    vdyn::TriangleMesh box;
    box.name = "box";
    box.kind = vdyn::SurfaceKind::kBarrier;
    box.AddBox({5, 5, 0}, {6, 6, 1});
    vdyn::World w;
    w.name = "seed";
    w.terrain.AddMesh(std::move(ground));
    w.terrain.AddMesh(std::move(box));
    w.terrain.Commit();
    Write(root / "world_description", "small.pb", vdyn::DescribeWorld(w, "seed", 1'000'000).SerializeAsString());
  }
  // What the server reads: inputs (first byte 0) and control requests (1).
  {
    vdyn::pb::DriverInput in;
    in.set_vehicle_id(1);
    in.set_source_id("seed-rig");
    in.set_throttle(0.6);
    in.set_steer(0.05);
    in.set_cruise_on(true);
    in.set_cruise_set_kmh(50);
    Write(root / "server_messages", "input.pb", Tagged('\0', in.SerializeAsString()));
    in.set_steer_mode(vdyn::pb::STEER_HAND_WHEEL);
    in.set_steer(1.5);
    in.set_gear(2);
    in.set_clutch(0.2);
    Write(root / "server_messages", "input_wheel.pb", Tagged('\0', in.SerializeAsString()));
    auto request = [&](const std::string& name, const vdyn::pb::ControlRequest& r) {
      Write(root / "server_messages", name, Tagged('\1', r.SerializeAsString()));
    };
    vdyn::pb::ControlRequest r;
    r.set_vehicle_id(1);
    r.set_client_id("seed");
    r.mutable_teleport()->mutable_pose()->set_x(-100);
    r.mutable_teleport()->mutable_pose()->set_y(-150);
    r.mutable_teleport()->set_speed(10);
    request("teleport.pb", r);
    r.mutable_set_params()->mutable_params()->set_mass(1700);
    request("set_params.pb", r);
    r.set_vehicle_id(2);
    r.set_server_id("fuzz");
    r.mutable_spawn()->mutable_pose()->set_x(0);
    r.mutable_spawn()->mutable_pose()->set_y(40);
    request("spawn.pb", r);
    r.mutable_step()->set_steps(3);
    request("step.pb", r);
    r.mutable_remove();
    request("remove.pb", r);
  }
  // Recordings: a small MCAP file per compression (two channels, chunks of a few messages,
  // metadata, a summary), and one cut short as a killed recorder leaves it.
  for (const auto& [name, compression] :
       {std::pair{"zstd.mcap", vdyn::mcap::Compression::kZstd},
        std::pair{"lz4.mcap", vdyn::mcap::Compression::kLz4},
        std::pair{"none.mcap", vdyn::mcap::Compression::kNone}}) {
    const fs::path path = root / "mcap" / name;
    fs::create_directories(path.parent_path());
    vdyn::mcap::WriterOptions options;
    options.compression = compression;
    options.chunk_bytes = 300;
    vdyn::mcap::Writer w(path, options);
    const std::uint16_t schema = w.AddSchema("vdyn.pb.VehicleState", "protobuf", "seed-descriptor");
    const std::uint16_t a = w.AddChannel(schema, "vdyn/state/1", "protobuf", {{"vehicle_id", "1"}});
    const std::uint16_t b = w.AddChannel(schema, "vdyn/state/2", "protobuf", {{"vehicle_id", "2"}});
    w.WriteMetadata("vdyn.recording", {{"format", "vdyn-recording 1"}, {"domain", "0"}});
    for (std::uint32_t i = 0; i < 12; ++i) {
      vdyn::pb::VehicleState s;
      s.set_vehicle_id(1 + i % 2);
      s.set_step(i);
      s.set_speed_kmh(10.0 * i);
      const std::string bytes = s.SerializeAsString();
      w.WriteMessage(i % 2 == 0 ? a : b, i / 2, 1'000'000 * (i + 1), 1'000'000 * i,
                     {reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()});
    }
    w.Close();
  }
  fs::copy_file(root / "mcap" / "zstd.mcap", root / "mcap" / "truncated.mcap",
                fs::copy_options::overwrite_existing);
  fs::resize_file(root / "mcap" / "truncated.mcap", fs::file_size(root / "mcap" / "zstd.mcap") * 2 / 3);
  // Drives for recover and verify: whole, without CRCs, and damaged as files get damaged.
  {
    const fs::path dir = root / "recover_verify";
    fs::create_directories(dir);
    WriteDrive(dir / "drive.mcap", true);
    WriteDrive(dir / "drive-nocrc.mcap", false);
    const std::string whole = ReadAll(dir / "drive.mcap");
    std::vector<vdyn::mcap::ChunkIndex> chunks = vdyn::mcap::Reader(dir / "drive.mcap").Chunks();
    if (chunks.size() < 4) std::abort();
    const vdyn::mcap::ChunkIndex& mid = chunks[chunks.size() / 2];
    std::string b = whole;
    b[mid.chunk_start_offset + mid.chunk_length / 2] ^= 0x40;  // a chunk's CRC fails
    Write(dir, "drive-lost-chunk.mcap", b);
    Write(dir, "drive-killed.mcap", whole.substr(0, whole.size() * 3 / 5));  // no summary
    b = whole;  // a chunk and its message indexes written twice
    const std::size_t at = mid.chunk_start_offset, n = mid.chunk_length + mid.message_index_length;
    b.insert(at + n, whole.substr(at, n));
    Write(dir, "drive-duplicate.mcap", b);
    b = ReadAll(dir / "drive-nocrc.mcap");  // a flipped byte that no chunk CRC checks
    b[chunks[1].chunk_start_offset + chunks[1].chunk_length / 2] ^= 0x10;
    fs::remove(dir / "drive-nocrc.mcap");
    Write(dir, "drive-nocrc-flipped.mcap", b);
  }
  std::printf("seeds written under %s\n", root.c_str());
  return 0;
}

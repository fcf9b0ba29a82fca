// The reference for tests/octomap_color.rs: OctoMap's own ColorOcTree, fed the same scans with
// the calls a colour mapper makes, written as a .ot.
//
// Usage: color_tree SCANS RES OUT.ot
//
// SCANS is the test's dump of the scans (little-endian): "RVCS", u32 scan count, then per scan
// seven f32 (tx ty tz qw qx qy qz: the sensor pose), u32 point count n, n x 3 f32 (x y z in the
// sensor frame), n x 3 u8 (r g b).
//
// Per scan, as graph2tree inserts it (points moved into the map frame by the pose, the sensor
// origin through the inverse pose and back, insertPointCloud without max range, lazy
// evaluation or discretisation); then for every point, in order, whose colour is not white
// (ColorOcTree's "no colour"): search the node holding its voxel and setNodeColor when the
// point is brighter (BT.601 luma, ties by r, g, b) or the node has no colour. At the end
// updateInnerOccupancy() (inner colours: the mean of their children's) and write().
#include <octomap/ColorOcTree.h>
#include <octomap/octomap.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

using namespace octomap;

namespace {

struct Reader {
  const std::vector<unsigned char>& bytes;
  size_t pos = 0;
  bool take(void* out, size_t n) {
    if (bytes.size() - pos < n) return false;
    std::memcpy(out, bytes.data() + pos, n);
    pos += n;
    return true;
  }
};

uint64_t brightness(uint8_t r, uint8_t g, uint8_t b) {
  uint64_t luma = 299u * r + 587u * g + 114u * b;
  return (luma << 24) | (uint64_t(r) << 16) | (uint64_t(g) << 8) | b;
}

int fail(const std::string& file, size_t offset, const std::string& what) {
  std::cerr << "color_tree: " << file << ": offset " << offset << ": " << what << "\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::cerr << "usage: color_tree SCANS RES OUT.ot\n";
    return 2;
  }
  const std::string in_name = argv[1];
  std::ifstream in(in_name, std::ios::binary);
  if (!in) return fail(in_name, 0, "cannot open");
  std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
  Reader rd{bytes};
  char magic[4];
  uint32_t scans = 0;
  if (!rd.take(magic, 4) || std::memcmp(magic, "RVCS", 4) != 0)
    return fail(in_name, 0, "expected magic RVCS");
  if (!rd.take(&scans, 4)) return fail(in_name, rd.pos, "expected the scan count");

  ColorOcTree tree(std::stod(argv[2]));
  for (uint32_t s = 0; s < scans; ++s) {
    float pose[7];
    uint32_t n = 0;
    if (!rd.take(pose, sizeof pose) || !rd.take(&n, 4))
      return fail(in_name, rd.pos, "scan " + std::to_string(s) + ": expected pose and count");
    if ((bytes.size() - rd.pos) / 15 < n)
      return fail(in_name, rd.pos, "scan " + std::to_string(s) + ": points cut short");
    Pointcloud pc;
    pc.reserve(n);
    for (uint32_t i = 0; i < n; ++i) {
      float p[3];
      rd.take(p, sizeof p);
      pc.push_back(p[0], p[1], p[2]);
    }
    std::vector<uint8_t> rgb(size_t(n) * 3);
    rd.take(rgb.data(), rgb.size());

    pose6d frame(point3d(pose[0], pose[1], pose[2]),
                 octomath::Quaternion(pose[3], pose[4], pose[5], pose[6]));
    point3d sensor = frame.inv().transform(frame.trans());
    pc.transform(frame);
    point3d origin = frame.transform(sensor);
    tree.insertPointCloud(pc, origin, -1, false, false);

    for (uint32_t i = 0; i < n; ++i) {
      uint8_t r = rgb[3 * i], g = rgb[3 * i + 1], b = rgb[3 * i + 2];
      if (r == 255 && g == 255 && b == 255) continue;
      OcTreeKey key;
      if (!tree.coordToKeyChecked(pc[i], key)) continue;
      ColorOcTreeNode* node = tree.search(key);
      if (node == NULL) continue;
      ColorOcTreeNode::Color c = node->getColor();
      if (!node->isColorSet() || brightness(r, g, b) > brightness(c.r, c.g, c.b))
        tree.setNodeColor(key, r, g, b);
    }
  }
  if (rd.pos != bytes.size()) return fail(in_name, rd.pos, "bytes after the last scan");
  tree.updateInnerOccupancy();
  if (!tree.write(argv[3])) {
    std::cerr << "color_tree: cannot write " << argv[3] << "\n";
    return 2;
  }
  std::cout << tree.size() << "\n";
  return 0;
}

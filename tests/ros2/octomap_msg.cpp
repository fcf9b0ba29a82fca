// Decodes the data of an octomap_msgs/msg/Octomap the way RViz's octomap plugin does
// (octomap_msgs' conversions: a binary message read with OcTree::readBinaryData, a full one
// with AbstractOcTree::createTree(id, resolution) and readData) with Debian's liboctomap, and
// writes the tree it gets: `.bt` (writeBinary) for a binary message, `.ot` (write) for a full
// one. With a map file given, also compares every leaf of each with the other's occupancy.
//
// usage: octomap_msg ID BINARY(0|1) RESOLUTION DATA_FILE OUT_FILE [MAP.ot]
// prints one JSON line: {"id":..., "nodes":N, "leaves":N, "mismatches":N}
#include <octomap/ColorOcTree.h>
#include <octomap/octomap.h>

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

using namespace octomap;

// Leaves of `a` whose occupancy `b` does not give at the same key and depth (b's node there,
// or the leaf above it).
template <class A, class B>
static size_t disagreements(const A& a, const B& b) {
    size_t bad = 0;
    for (auto it = a.begin_leafs(), end = a.end_leafs(); it != end; ++it) {
        auto* n = b.search(it.getKey(), it.getDepth());
        if (n == nullptr || b.isNodeOccupied(n) != a.isNodeOccupied(*it)) bad++;
    }
    return bad;
}

template <class T>
static int compare_with(const T& tree, AbstractOcTree* map, size_t* bad) {
    if (auto* c = dynamic_cast<ColorOcTree*>(map)) {
        *bad = disagreements(tree, *c) + disagreements(*c, tree);
        return 0;
    }
    if (auto* o = dynamic_cast<OcTree*>(map)) {
        *bad = disagreements(tree, *o) + disagreements(*o, tree);
        return 0;
    }
    return 1;
}

int main(int argc, char** argv) {
    if (argc < 6) {
        std::cerr << "usage: octomap_msg ID BINARY RESOLUTION DATA OUT [MAP.ot]\n";
        return 2;
    }
    std::string id = argv[1];
    bool binary = std::string(argv[2]) == "1";
    double res = std::atof(argv[3]);
    std::ifstream f(argv[4], std::ios::binary);
    std::stringstream data;
    data << f.rdbuf();
    AbstractOcTree* map = argc > 6 ? AbstractOcTree::read(argv[6]) : nullptr;
    if (argc > 6 && map == nullptr) {
        std::cerr << "cannot read " << argv[6] << "\n";
        return 1;
    }
    size_t bad = 0, nodes = 0, leaves = 0;
    if (binary) {
        if (id != "OcTree") {
            std::cerr << "binary message of type " << id << "\n";
            return 1;
        }
        OcTree tree(res);
        if (!tree.readBinaryData(data)) {
            std::cerr << "readBinaryData failed\n";
            return 1;
        }
        tree.writeBinary(argv[5]);
        nodes = tree.size();
        leaves = tree.getNumLeafNodes();
        if (map && compare_with(tree, map, &bad) != 0) return 1;
    } else {
        AbstractOcTree* t = AbstractOcTree::createTree(id, res);
        if (t == nullptr) {
            std::cerr << "unknown tree type " << id << "\n";
            return 1;
        }
        auto* occ = dynamic_cast<AbstractOccupancyOcTree*>(t);
        if (occ == nullptr || !t->readData(data)) {
            std::cerr << "readData failed\n";
            return 1;
        }
        t->write(argv[5]);
        nodes = t->size();
        if (auto* c = dynamic_cast<ColorOcTree*>(t)) {
            leaves = c->getNumLeafNodes();
            if (map && compare_with(*c, map, &bad) != 0) return 1;
        } else if (auto* o = dynamic_cast<OcTree*>(t)) {
            leaves = o->getNumLeafNodes();
            if (map && compare_with(*o, map, &bad) != 0) return 1;
        }
    }
    std::cout << "{\"id\":\"" << id << "\",\"nodes\":" << nodes << ",\"leaves\":" << leaves
              << ",\"mismatches\":" << bad << "}" << std::endl;
    return 0;
}

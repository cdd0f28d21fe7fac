// Loader for protocol/vectors/frames.txt (format: protocol/spec.md §7).
#pragma once
#include <cstdint>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

struct Vector {
    std::string name;
    std::map<std::string, std::string> fields;  // every key = value line, in raw text
    std::vector<uint8_t> wire;
    std::string get(const std::string& k) const {
        auto it = fields.find(k);
        return it == fields.end() ? std::string() : it->second;
    }
    bool has(const std::string& k) const { return fields.count(k) != 0; }
};

inline std::string trim(const std::string& s) {
    size_t a = s.find_first_not_of(" \t\r\n"), b = s.find_last_not_of(" \t\r\n");
    return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
}

inline std::vector<uint8_t> parseHex(const std::string& s) {
    std::vector<uint8_t> out;
    std::string t;
    for (char c : s)
        if (!std::isspace((unsigned char)c)) t += c;
    for (size_t i = 0; i + 1 < t.size(); i += 2) out.push_back((uint8_t)std::stoul(t.substr(i, 2), nullptr, 16));
    return out;
}

inline std::vector<long> parseInts(const std::string& s) {
    std::vector<long> out;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ','))
        if (!trim(item).empty()) out.push_back(std::stol(trim(item), nullptr, 0));
    return out;
}

inline std::vector<Vector> loadVectors(const std::string& path) {
    std::vector<Vector> out;
    std::ifstream in(path);
    std::string line;
    while (std::getline(in, line)) {
        std::string t = trim(line);
        if (t.empty() || t[0] == '#') continue;
        if (t[0] == '[') {
            out.push_back(Vector());
            out.back().name = t.substr(1, t.find(']') - 1);
            continue;
        }
        size_t eq = line.find('=');
        if (eq == std::string::npos || out.empty()) continue;
        std::string k = trim(line.substr(0, eq)), v = trim(line.substr(eq + 1));
        out.back().fields[k] = v;
        if (k == "wire") out.back().wire = parseHex(v);
    }
    return out;
}

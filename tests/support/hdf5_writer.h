// Small HDF5 snapshot files written with the C API, for the reader's tests
// and the fuzzer's seeds: attributes in groups, datasets by path
// ("PartType1/Coordinates"), contiguous or in deflated chunks.
#pragma once

#include <hdf5.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace octocosm::testing_support {

class Hdf5Writer {
 public:
  // `chunked`: datasets in chunks of two rows, deflated; contiguous otherwise.
  explicit Hdf5Writer(const std::string& path, bool chunked = false) : chunked_(chunked) {
    file_ = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    if (file_ < 0) throw std::runtime_error("cannot create the HDF5 file " + path);
    H5Gclose(Group("Header"));
  }
  ~Hdf5Writer() { H5Fclose(file_); }
  Hdf5Writer(const Hdf5Writer&) = delete;
  Hdf5Writer& operator=(const Hdf5Writer&) = delete;

  template <typename T>
  void Attribute(const char* group, const char* name, hid_t type, const std::vector<T>& values) {
    const hid_t location = Group(group);
    const hsize_t dims[1] = {values.size()};
    const hid_t space = H5Screate_simple(1, dims, nullptr);
    const hid_t attribute = H5Acreate2(location, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attribute, type, values.data());
    H5Aclose(attribute);
    H5Sclose(space);
    H5Gclose(location);
  }
  // `values` row by row, `columns` to a row (1: a one-dimensional dataset).
  template <typename T>
  void Dataset(const std::string& path, hid_t type, const std::vector<T>& values, hsize_t columns) {
    H5Gclose(Group(path.substr(0, path.find('/')).c_str()));
    const hsize_t dims[2] = {values.size() / columns, columns};
    const int rank = columns == 1 ? 1 : 2;
    const hid_t space = H5Screate_simple(rank, dims, nullptr);
    const hid_t properties = H5Pcreate(H5P_DATASET_CREATE);
    if (chunked_) {
      const hsize_t chunk[2] = {2, columns};
      H5Pset_chunk(properties, rank, chunk);
      H5Pset_deflate(properties, 1);
    }
    const hid_t dataset = H5Dcreate2(file_, path.c_str(), type, space, H5P_DEFAULT, properties, H5P_DEFAULT);
    H5Dwrite(dataset, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data());
    H5Dclose(dataset);
    H5Pclose(properties);
    H5Sclose(space);
  }

 private:
  hid_t Group(const char* name) {
    if (H5Lexists(file_, name, H5P_DEFAULT) > 0) return H5Gopen2(file_, name, H5P_DEFAULT);
    return H5Gcreate2(file_, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  }
  bool chunked_;
  hid_t file_;
};

}  // namespace octocosm::testing_support
